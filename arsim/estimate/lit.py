"""A light estimate as a renderer lights with it (README: Light estimation), the way the platforms' samples
use their estimates:

- diffuse: the SH ambient without the main light (its projection, intensity x Y_lm(direction), taken out of
  `sh_radiance`, which holds the whole light) plus the main light as a directional light,
  E(n) = sum A_l (L_lm - I Y_lm(l)) Y_lm(n) + I max(0, n . l), clamped at 0;
- reflections: the cubemap, filtered by the normalised Phong lobe of each exponent over its texels;
- as maps: a MapSet per map method whose irradiance map (exponent 1) is E / pi and whose reflection maps
  are those lobe averages, at the angle map's texel directions (lighting.mapset's convention: a constant
  light gives that constant), so that the renderer lights any object with an estimate as with a probe;
- as an angle map (`environment`): the cubemap's texel in each direction, for what is baked from a light
  rather than read from maps (directional light maps, PRT transfer, the irradiance volume).
"""

from __future__ import annotations

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask
from arsim.estimate.shapes import LightEstimate, cube_directions, cube_solid_angles, cube_texels
from arsim.lighting.bases.functions import sh9
from arsim.lighting.bases.irradiance import COSINE_KERNEL
from arsim.lighting.mapset import MapSet

CHUNK = 8192  # directions per block of the lobe sums (keeps the (directions x cube texels) products small)


def irradiance(sh_radiance: np.ndarray, direction: np.ndarray, intensity: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(K, 3) irradiance at unit normals (K, 3): the SH ambient without the main light, plus the main light
    as a directional light (see the module's docstring)."""
    l = np.asarray(direction, dtype=np.float64)
    l = l / max(np.linalg.norm(l), 1e-300)
    i = np.asarray(intensity, dtype=np.float64)
    ambient = np.asarray(sh_radiance, dtype=np.float64).reshape(9, 3) - sh9(l[None])[0][:, None] * i[None]
    n = np.asarray(normals, dtype=np.float64)
    return np.maximum(sh9(n) @ (ambient * COSINE_KERNEL[:, None]) + np.maximum(n @ l, 0.0)[:, None] * i[None], 0.0)


def estimate_irradiance(e: LightEstimate, normals: np.ndarray) -> np.ndarray:
    """(K, 3) an estimate's irradiance at unit normals (K, 3)."""
    return irradiance(e.sh_radiance, e.main_light_direction, e.main_light_intensity, normals)


def lobe_average(cubemap: np.ndarray, directions: np.ndarray, exponent: float) -> np.ndarray:
    """(K, 3) the normalised Phong lobe's average of a cubemap (6, N, N, 3) about unit directions (K, 3)."""
    side = np.asarray(cubemap).shape[1]
    return lobe_average_of(cube_directions(side).reshape(-1, 3), np.asarray(cubemap, dtype=np.float64).reshape(-1, 3),
                           np.tile(cube_solid_angles(side).reshape(-1), 6), directions, exponent)


def lobe_average_of(samples: np.ndarray, radiance: np.ndarray, weights: np.ndarray, directions: np.ndarray,
                    exponent: float) -> np.ndarray:
    """(K, 3) sum L w max(0, d . s)^e / sum w max(0, d . s)^e over samples s (M, 3) of radiance L (M, 3) with
    solid angles w (M,), about unit directions d (K, 3)."""
    d = np.asarray(directions, dtype=np.float64)
    out = np.empty((len(d), 3))
    for start in range(0, len(d), CHUNK):
        cos = np.maximum(d[start:start + CHUNK] @ samples.T, 0.0)
        # (scaled by the largest cosine before the power: a narrow lobe between samples does not underflow)
        lobe = (cos / np.maximum(cos.max(axis=1, keepdims=True), 1e-300)) ** exponent * weights[None]
        out[start:start + CHUNK] = (lobe @ radiance) / np.maximum(lobe.sum(axis=1), 1e-300)[:, None]
    return out


def estimate_maps(e: LightEstimate, needed: dict[str, list[float]], size: int, source: str) -> dict[str, MapSet]:
    """A MapSet per map method the objects need (the same maps under each name: an estimate is not baked by
    a method), size² angle maps, 0 off the disk."""
    inside = anglemap_disk_mask(size)
    d = anglemap_directions(size)[inside]
    exponents = sorted({float(s) for ss in needed.values() for s in ss} | {1.0})
    maps = {}
    for s in exponents:
        image = np.zeros((size, size, 3), np.float32)
        image[inside] = estimate_irradiance(e, d) / np.pi if s == 1.0 else lobe_average(e.cubemap, d, s)
        maps[s] = image
    return {name: MapSet(name, {s: maps[float(s)] for s in {1.0, *exponents_}}, source)
            for name, exponents_ in needed.items()}


def environment(e: LightEstimate, size: int) -> np.ndarray:
    """(size, size, 3) float32 angle map of the estimate's cubemap (each direction its texel's radiance)."""
    inside = anglemap_disk_mask(size)
    f, r, c = cube_texels(anglemap_directions(size)[inside], e.cubemap.shape[1])
    out = np.zeros((size, size, 3), np.float32)
    out[inside] = np.asarray(e.cubemap)[f, r, c]
    return out
