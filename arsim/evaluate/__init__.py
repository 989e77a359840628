"""Evaluation: every stage measured against the truth (capture, tracking, session, profile), method
comparisons, and the visual-regression diff."""

from arsim.core.public import lazy_names

__all__, __getattr__ = lazy_names(__name__, {
    "capture_report": ("capture_metrics", "write_capture"),
    "tracking": ("measure_poses", "TrackingRun"),
    "session": ("session_metrics",),
    "profile": ("ProfileRun", "write_profile"),
    "diff": ("run_diff",),
    "flip": ("masked_flip",),
    "metrics": ("map_error",),
})
