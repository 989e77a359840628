"""Evaluation: every stage measured against the truth (capture, tracking, session, profile), method
comparisons, and the visual-regression diff."""

_PUBLIC = {
    "capture_metrics": "arsim.evaluate.capture_report",
    "write_capture": "arsim.evaluate.capture_report",
    "measure_poses": "arsim.evaluate.tracking",
    "TrackingRun": "arsim.evaluate.tracking",
    "session_metrics": "arsim.evaluate.session",
    "ProfileRun": "arsim.evaluate.profile",
    "write_profile": "arsim.evaluate.profile",
    "run_diff": "arsim.evaluate.diff",
    "masked_flip": "arsim.evaluate.diff",
    "map_error": "arsim.evaluate.metrics",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    """The public names, imported when first used (importing the package stays cheap)."""
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
