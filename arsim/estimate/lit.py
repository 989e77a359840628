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

import numba
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


# A sample whose lobe term falls below e^-LOBE_CUTOFF of the largest one's adds less than float64 resolves
# to the sums: skipped (narrow lobes then cost a few samples each, not all of them).
LOBE_CUTOFF = 60.0


@numba.njit(parallel=True, cache=True, nogil=True)
def _lobe_averages(samples, radiance, weights, directions, exponents, out):
    for k in numba.prange(directions.shape[0]):
        d0, d1, d2 = directions[k, 0], directions[k, 1], directions[k, 2]
        cos = np.empty(samples.shape[0])
        top = 0.0
        for m in range(samples.shape[0]):
            c = d0 * samples[m, 0] + d1 * samples[m, 1] + d2 * samples[m, 2]
            cos[m] = c
            top = max(top, c)
        top = max(top, 1e-300)
        for m in range(samples.shape[0]):  # (log of the ratio to the largest cosine, shared by the exponents)
            cos[m] = np.log(cos[m] / top) if cos[m] > 0.0 else -np.inf
        for e in range(exponents.shape[0]):
            s = exponents[e]
            r, g, b, den = 0.0, 0.0, 0.0, 0.0
            for m in range(samples.shape[0]):
                t = s * cos[m]
                if t > -LOBE_CUTOFF:
                    w = np.exp(t) * weights[m]
                    r += w * radiance[m, 0]
                    g += w * radiance[m, 1]
                    b += w * radiance[m, 2]
                    den += w
            den = max(den, 1e-300)
            out[e, k, 0], out[e, k, 1], out[e, k, 2] = r / den, g / den, b / den


def lobe_averages_of(samples: np.ndarray, radiance: np.ndarray, weights: np.ndarray, directions: np.ndarray,
                     exponents) -> np.ndarray:
    """(E, K, 3) lobe_average_of for several exponents at once, compiled: each sample's cosine computed once
    for all exponents, terms below e^-LOBE_CUTOFF of the largest skipped (lobe_average_of is its reference)."""
    d = np.ascontiguousarray(directions, dtype=np.float64)
    out = np.empty((len(exponents), len(d), 3))
    _lobe_averages(np.ascontiguousarray(samples, dtype=np.float64), np.ascontiguousarray(radiance, dtype=np.float64),
                   np.ascontiguousarray(weights, dtype=np.float64), d, np.asarray(exponents, dtype=np.float64), out)
    return out


def estimate_maps(e: LightEstimate, needed: dict[str, list[float]], size: int, source: str) -> dict[str, MapSet]:
    """A MapSet per map method the objects need (the same maps under each name: an estimate is not baked by
    a method), size² angle maps, 0 off the disk."""
    inside = anglemap_disk_mask(size)
    d = anglemap_directions(size)[inside]
    exponents = sorted({float(s) for ss in needed.values() for s in ss} | {1.0})
    side = e.cubemap.shape[1]
    lobes = [s for s in exponents if s != 1.0]
    averages = lobe_averages_of(cube_directions(side).reshape(-1, 3), np.asarray(e.cubemap).reshape(-1, 3),
                                np.tile(cube_solid_angles(side).reshape(-1), 6), d, lobes)
    maps = {}
    for s in exponents:
        image = np.zeros((size, size, 3), np.float32)
        image[inside] = estimate_irradiance(e, d) / np.pi if s == 1.0 else averages[lobes.index(s)]
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
