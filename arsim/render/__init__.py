"""The AR session's renderer: virtual objects lit by image-based lighting (irradiance and reflection maps),
light maps and normal maps, tone-mapped through a mask over the camera image (thesis chapter 5)."""

_PUBLIC = {
    "Renderer": "arsim.render.renderer",
    "SceneObject": "arsim.render.renderer",
    "Material": "arsim.render.renderer",
    "scene_objects": "arsim.render.content",
    "light_objects": "arsim.render.content",
    "run_session": "arsim.render.session",
    "run_profile": "arsim.render.session",
    "SessionSettings": "arsim.render.session",
    "SessionResult": "arsim.render.session",
    "BakeSettings": "arsim.render.baking",
    "LoopBaker": "arsim.render.baking",
}
__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    """The public names, imported when first used (importing the package stays cheap)."""
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
