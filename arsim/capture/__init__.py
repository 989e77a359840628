"""HDR capture (spec chapter 3, Kán's method): response calibration from the recording's burst, frames
accumulated into an angle-map light probe, and feature-based correction of the IMU's drift."""
