"""Synthetic sensors: ground-truth device trajectories, the IMU streams a phone would report, its camera,
and recordings of them."""

_PUBLIC = {
    "record": "arsim.sensors.recording",
    "load_recording": "arsim.sensors.recording",
    "Recording": "arsim.sensors.recording",
    "recording_camera": "arsim.sensors.frames",
    "frame_camera_orientations": "arsim.sensors.frames",
    "frame_positions": "arsim.sensors.frames",
    "simulate_imu": "arsim.sensors.imu",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    """The public names, imported when first used (importing the package stays cheap)."""
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
