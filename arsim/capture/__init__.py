"""HDR capture (spec chapter 3, Kán's method): response calibration from the recording's burst, frames
accumulated into an angle-map light probe, the IMU's drift corrected online and by the global refinement."""

_PUBLIC = {
    "capture": "arsim.capture.pipeline",
    "CaptureSettings": "arsim.capture.pipeline",
    "CaptureResult": "arsim.capture.pipeline",
    "calibrate_response": "arsim.capture.response",
    "RecoveredResponse": "arsim.capture.response",
    "ProbeAccumulator": "arsim.capture.accumulate",
    "filled": "arsim.capture.accumulate",
    "refine": "arsim.capture.refine",
    "Refinement": "arsim.capture.refine",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    """The public names, imported when first used (importing the package stays cheap)."""
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
