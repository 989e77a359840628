"""Runs: the steps the commands run (stages.py), a scenario end to end into a run directory with its
report and manifest (pipeline.py), and many of them at once (batch.py)."""

_PUBLIC = {
    "run_scenario": "arsim.run.pipeline",
    "check_run": "arsim.run.pipeline",
    "measured_capture": "arsim.run.stages",
    "render_session": "arsim.run.stages",
    "profile_session": "arsim.run.stages",
    "session_inputs": "arsim.run.stages",
    "run_batch": "arsim.run.batch",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    """The public names, imported when first used (importing the package stays cheap)."""
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
