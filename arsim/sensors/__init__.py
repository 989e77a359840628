"""Synthetic sensors: ground-truth device trajectories, the IMU streams a phone would report, its camera,
and recordings of them."""

from arsim.core.public import lazy_names

__all__, __getattr__ = lazy_names(__name__, {
    "recording": ("record", "load_recording", "Recording"),
    "frames": ("recording_camera", "frame_camera_orientations", "frame_positions", "recording_scenario", "truth_absent"),
    "imu": ("simulate_imu",),
})
