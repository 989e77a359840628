"""AprilTag tracking: the tag's pose in each camera frame, as the AR session's view matrix."""

_PUBLIC = {
    "TagTracker": "arsim.tracking.apriltag",
    "TagPose": "arsim.tracking.apriltag",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    """The public names, imported when first used (importing the package stays cheap)."""
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
