"""AprilTag tracking: the tag's pose in each camera frame, as the AR session's view matrix."""

from arsim.core.public import lazy_names

__all__, __getattr__ = lazy_names(__name__, {
    "apriltag": ("TagTracker", "TagPose"),
})
