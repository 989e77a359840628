"""HDR capture (spec chapter 3, Kán's method): response calibration from the recording's burst, frames
accumulated into an angle-map light probe, the IMU's drift corrected online and by the global refinement."""

from arsim.core.public import lazy_names

__all__, __getattr__ = lazy_names(__name__, {
    "pipeline": ("capture", "CaptureSettings", "CaptureResult"),
    "response": ("calibrate_response", "RecoveredResponse"),
    "accumulate": ("ProbeAccumulator", "filled"),
    "refine": ("refine", "Refinement"),
})
