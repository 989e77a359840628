"""The AR session's renderer: virtual objects lit by image-based lighting (irradiance and reflection maps),
light maps and normal maps, tone-mapped through a mask over the camera image (thesis chapter 5)."""

from arsim.core.public import lazy_names

__all__, __getattr__ = lazy_names(__name__, {
    "renderer": ("Renderer", "SceneObject", "Material"),
    "content": ("scene_objects", "light_objects"),
    "session": ("run_session", "run_profile", "SessionSettings", "SessionResult"),
    "baking": ("BakeSettings", "LoopBaker"),
})
