"""Runs: the steps the commands run (stages.py), a scenario end to end into a run directory with its
report and manifest (pipeline.py), and many of them at once (batch.py)."""

from arsim.core.public import lazy_names

__all__, __getattr__ = lazy_names(__name__, {
    "pipeline": ("run_scenario", "check_run"),
    "stages": ("measured_capture", "render_session", "profile_session", "session_inputs"),
    "batch": ("run_batch",),
})
