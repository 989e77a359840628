"""Light estimation as phones report it (README: Light estimation): from a light (an angle map, as the truth
or the capture has it), the shapes ARCore, ARKit and WebXR report: SH of the radiance (bands 0-2), a main
light, a small HDR cubemap, an ambient intensity and a colour correction.

shapes.py   the estimate of an angle-map light, and its parts
"""

from arsim.core.public import lazy_names

__all__, __getattr__ = lazy_names(__name__, {"shapes": ("LightEstimate", "estimate_light", "cube_directions")})
