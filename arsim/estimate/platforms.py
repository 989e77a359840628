"""A light estimate in each platform's own structure and field names (README: Light estimation), so that
a renderer written against ARCore, ARKit or WebXR can be fed from arsim:

- ARCore (Environmental HDR mode): `mainLightDirection` (towards the light, world), `mainLightIntensity`
  (RGB), `ambientSphericalHarmonics` (27 floats, [r0, g0, b0, r1, ...]: ARCore's basis carries the
  Condon-Shortley phase, so the coefficients of m = -1 and +1 have the opposite sign of arsim's; its
  samples' shader factors, 0.282095, -0.325735, ..., turn them back), `cubemap` (6 faces +X..-Z, 16 x 16
  RGB, OpenGL's order), and the Ambient Intensity mode's `colorCorrection` (R/G, 1, B/G, intensity) and
  `pixelIntensity`.
- ARKit (ARDirectionalLightEstimate): `sphericalHarmonicsCoefficients` (27 floats in three planes: the
  nine of red, then green, then blue), `primaryLightDirection` (towards the light), `primaryLightIntensity`
  and `ambientIntensity` (lumens, 1000 neutral: 1000 x the ambient intensity, arsim's radiance taken as
  relative to a neutral 1), `ambientColorTemperature` (kelvin, from the mean colour's chromaticity by
  McCamy's formula; 6500 neutral).
- WebXR (XRLightEstimate): `sphericalHarmonicsCoefficients` (27 floats, RGB interleaved, in arsim's basis,
  the one three.js's XREstimatedLight reads them in), `primaryLightDirection` (towards the light),
  `primaryLightIntensity` (RGB), and the reflection cube map (`reflectionCubeMap`, as ARCore's).
"""

from __future__ import annotations

import numpy as np

from arsim.estimate.shapes import LightEstimate
from arsim.lighting.bases.projection import CONDON_SHORTLEY  # (-1)^m of the nine SH

# linear sRGB (Rec. 709 primaries, D65) to CIE XYZ
SRGB_TO_XYZ = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])


def color_temperature_k(rgb: np.ndarray) -> float:
    """Correlated colour temperature (K) of a linear sRGB colour: its chromaticity by McCamy's cubic (good
    from about 2000 to 12500 K)."""
    x_, y_, z_ = SRGB_TO_XYZ @ np.asarray(rgb, dtype=np.float64)
    total = x_ + y_ + z_
    if total <= 0:
        return 6500.0
    x, y = x_ / total, y_ / total
    n = (x - 0.3320) / (0.1858 - y)
    return float(449 * n ** 3 + 3525 * n ** 2 + 6823.3 * n + 5520.33)


def _floats(a) -> list[float]:
    return [float(v) for v in np.asarray(a, dtype=np.float64).reshape(-1)]


def arcore(e: LightEstimate) -> dict:
    return {"mainLightDirection": _floats(e.main_light_direction), "mainLightIntensity": _floats(e.main_light_intensity),
            "ambientSphericalHarmonics": _floats(e.sh_radiance * CONDON_SHORTLEY[:, None]),
            "cubemap": [_floats(face) for face in e.cubemap], "cubemapSize": int(e.cubemap.shape[1]),
            "colorCorrection": _floats(e.color_correction), "pixelIntensity": float(e.ambient_intensity)}


def arkit(e: LightEstimate) -> dict:
    mean_rgb = np.asarray(e.color_correction[:3], dtype=np.float64)
    return {"sphericalHarmonicsCoefficients": _floats(np.asarray(e.sh_radiance).T),
            "primaryLightDirection": _floats(e.main_light_direction),
            "primaryLightIntensity": float(1000 * (np.asarray(e.main_light_intensity) @ SRGB_TO_XYZ[1])),
            "ambientIntensity": float(1000 * e.ambient_intensity), "ambientColorTemperature": color_temperature_k(mean_rgb)}


def webxr(e: LightEstimate) -> dict:
    return {"sphericalHarmonicsCoefficients": _floats(e.sh_radiance),
            "primaryLightDirection": _floats(e.main_light_direction) + [0.0],
            "primaryLightIntensity": _floats(e.main_light_intensity) + [1.0],
            "reflectionCubeMap": [_floats(face) for face in e.cubemap], "reflectionCubeMapSize": int(e.cubemap.shape[1])}


PLATFORMS = {"arcore": arcore, "arkit": arkit, "webxr": webxr}
