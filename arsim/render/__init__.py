"""The AR session's renderer: virtual objects lit by image-based lighting (irradiance and reflection maps),
light maps and normal maps, tone-mapped through a mask over the camera image (thesis chapter 5)."""
