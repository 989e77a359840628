"""The shapes of a light estimate, from an angle-map light in world axes (README: Light estimation).

- `sh_radiance` (9, 3): the radiance's coefficients L_lm in the real orthonormal SH basis of bands 0-2,
  ordered (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1), (2,0), (2,1), (2,2), of the world direction
  (x, y, z) as three.js and WebXR write them (Y1-1 ~ y, Y10 ~ z, Y11 ~ x; bases.functions.sh9), so that
  the irradiance is E(n) = sum A_l L_lm Y_lm(n), A_l = pi, 2 pi / 3, pi / 4. By the sum over the angle
  map's disk texels with their solid angles, in float64 (lighting.bases.projection.sh_radiance, which the
  maps' export uses too).
- `main_light`: the brightest region (the texels connected to the brightest one whose luminance is at
  least MAIN_LIGHT_SHARE of its) as a direction (its energy-weighted centroid, world axes) and an RGB
  intensity (its first moment along that direction, sum L w (d . l): the irradiance it gives a surface
  facing it where it is compact, less as it spreads: main_light_intensity).
- `cubemap` (6, N, N, 3): radiance on the faces +X, -X, +Y, -Y, +Z, -Z in OpenGL's cube-map convention
  (face texel (row r, column c) at s = (c + 0.5) / N, t = (r + 0.5) / N: core.conventions.cube_directions), each texel the
  solid-angle weighted mean radiance of the light's texels in it (a box filter over the sphere).
- `ambient_intensity`: the mean luminance (Rec. 709 weights) of the radiance over the sphere;
  `color_correction` (4): ARCore's ambient mode's shape, the mean radiance's RGB over its green, and the
  ambient intensity.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
import scipy.sparse

from arsim.core.conventions import anglemap_st_to_pixel, direction_to_anglemap_st, normalize
from arsim.core.conventions import cube_directions, cube_solid_angles, cube_texels  # noqa: F401  (the estimates' cube maps)
from arsim.core.resample import beyond_rim_indices
from arsim.lighting.bases.functions import sh9
from arsim.lighting.bases.projection import disk_geometry as _disk_geometry
from arsim.lighting.bases.projection import disk_samples as _disk
from arsim.lighting.bases.projection import sh_radiance  # noqa: F401  (one rule, in lighting; estimates use it here)
from arsim.sensors.camera import LUMA  # Rec. 709, linear

MAIN_LIGHT_SHARE = 0.5  # the main light: texels at least this share of the brightest one's luminance
CUBE_SIZE = 16  # ARCore's environmental HDR cubemap: 16 x 16 per face
SPLAT_SIDE = 16 * CUBE_SIZE  # the angle map's side the cubemap is summed from (at least; about 33 texels a cube texel)


@dataclass(frozen=True)
class LightEstimate:
    sh_radiance: np.ndarray  # (9, 3)
    main_light_direction: np.ndarray  # (3,) unit, world
    main_light_intensity: np.ndarray  # (3,) RGB, radiance x sr
    cubemap: np.ndarray  # (6, N, N, 3)
    ambient_intensity: float
    color_correction: np.ndarray  # (4,)


def main_light(anglemap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(direction (3,), intensity (3,)) of the brightest region (see the module's docstring)."""
    light = np.asarray(anglemap, dtype=np.float64)[..., :3]
    inside, directions, omega = _disk_geometry(light.shape[0])
    luminance = np.where(inside, light @ LUMA, 0.0)
    brightest = np.unravel_index(np.argmax(luminance), luminance.shape)
    bright = (luminance >= MAIN_LIGHT_SHARE * luminance[brightest]).astype(np.uint8)
    _, labels = cv2.connectedComponents(bright, connectivity=8)
    region = (labels == labels[brightest])[inside]  # (over the disk's texels)
    weights = luminance[inside][region] * omega[region]
    d = directions[region]
    direction = normalize((d * weights[:, None]).sum(axis=0))
    return direction, main_light_intensity(light[inside][region], omega[region], d, direction)


def main_light_intensity(radiance: np.ndarray, omega: np.ndarray, directions: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(3,) a region's first moment along its direction, sum L w (d . l): the irradiance it gives a surface
    facing it where it is compact (a sun), falling to 0 as it spreads around the sphere (a uniform light
    has no direction to give), so that it can stand as a directional light (estimate.lit)."""
    return (radiance * (omega * (directions @ direction))[:, None]).sum(axis=0)


def cubemap(anglemap: np.ndarray, size: int = CUBE_SIZE) -> np.ndarray:
    """(6, size, size, 3) float32: the light on the cube's faces, each texel the solid-angle weighted mean
    radiance of the angle-map texels that fall in it: a box filter, so that a small sun's energy lands in
    one texel (point samples miss it or multiply it), and a uniform light stays uniform (dividing by the
    texel's exact solid angle instead would make each texel as bright as the count of angle-map texels that
    happen to fall in it: +-10 % at 512², +-23 % at 64²). A light coarser than SPLAT_SIDE is read at a
    SPLAT_SIDE angle map's texels, so that every cube texel gets many (_cube_operator)."""
    light = np.asarray(anglemap, dtype=np.float64)[..., :3]
    n = light.shape[0]
    return (_cube_operator(n, size) @ light.reshape(n * n, 3)).reshape(6, size, size, 3).astype(np.float32)


@functools.lru_cache(maxsize=8)
def _cube_operator(n: int, size: int) -> scipy.sparse.csr_matrix:
    """cubemap() as a sparse matrix (6 size², N²) over an N x N angle map's texels, built once a size: the
    means are linear in the light, so a frame's estimate is one sparse product. A light coarser than
    SPLAT_SIDE is read bilinearly at a SPLAT_SIDE angle map's texel centres (as core.resample.to_layout
    resamples: edges clamp, texels beyond the rim take their nearest inside)."""
    side = max(n, SPLAT_SIDE)
    inside, d, omega = _disk_geometry(side)
    if side == n:  # the light's own texels
        source, weight = np.flatnonzero(inside)[:, None], np.ones((len(d), 1))
    else:
        rows, cols = anglemap_st_to_pixel(direction_to_anglemap_st(d), n)
        r0, c0 = np.floor(rows).astype(int), np.floor(cols).astype(int)
        fr, fc = rows - r0, cols - c0
        ri, ci = beyond_rim_indices(n)
        source, weight = [], []
        for dr, dc, w in ((0, 0, (1 - fr) * (1 - fc)), (0, 1, (1 - fr) * fc), (1, 0, fr * (1 - fc)), (1, 1, fr * fc)):
            r, c = np.clip(r0 + dr, 0, n - 1), np.clip(c0 + dc, 0, n - 1)
            source.append(ri[r, c] * n + ci[r, c])
            weight.append(w)
        source, weight = np.stack(source, axis=1), np.stack(weight, axis=1)
    texel = _cube_texel_index(d, size)
    per_texel = np.bincount(texel, weights=omega, minlength=6 * size * size)
    values = weight * (omega / np.maximum(per_texel[texel], 1e-300))[:, None]
    rows_ = np.repeat(texel, source.shape[1])
    return scipy.sparse.csr_matrix((values.ravel(), (rows_, source.ravel())), shape=(6 * size * size, n * n))


def _cube_texel_index(directions: np.ndarray, size: int) -> np.ndarray:
    """(K,) the flat index (face, row, col) of the cube texel each unit direction falls in."""
    face, row, col = cube_texels(directions, size)
    return (face * size + row) * size + col


def cube_means(directions: np.ndarray, radiance: np.ndarray, omega: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """((6, size, size, 3) the solid-angle weighted mean radiance of the samples (directions (K, 3), radiance
    (K, 3), solid angles (K,)) that fall in each cube texel, 0 where none does; (6, size, size) their solid
    angle per texel)."""
    texel, count = _cube_texel_index(directions, size), 6 * size * size
    weighted = radiance * omega[:, None]
    sums = np.stack([np.bincount(texel, weights=weighted[:, c], minlength=count) for c in range(3)], axis=-1)
    weights = np.bincount(texel, weights=omega, minlength=count)
    return (sums / np.maximum(weights, 1e-300)[:, None]).reshape(6, size, size, 3), weights.reshape(6, size, size)


def sh_cubemap(sh_radiance: np.ndarray, size: int = CUBE_SIZE) -> np.ndarray:
    """(6, size, size, 3) the radiance of SH coefficients (9, 3) at the texel centres, clamped at 0."""
    return np.maximum(_cube_sh9(size) @ np.asarray(sh_radiance, dtype=np.float64).reshape(9, 3), 0.0).reshape(6, size, size, 3)


@functools.lru_cache(maxsize=4)
def _cube_sh9(size: int) -> np.ndarray:
    """(6 size², 9) the SH basis at the cube's texel centres, once a size."""
    return sh9(cube_directions(size).reshape(-1, 3))


def estimate_light(anglemap: np.ndarray) -> LightEstimate:
    """Every shape of an angle-map light (world axes)."""
    d, radiance, omega = _disk(anglemap)
    mean = (radiance * omega[:, None]).sum(axis=0) / omega.sum()
    ambient = float(mean @ LUMA)
    green = mean[1] if mean[1] > 0 else 1.0
    direction, intensity = main_light(anglemap)
    return LightEstimate(sh_radiance(anglemap), direction, intensity, cubemap(anglemap), ambient,
                         np.array([mean[0] / green, 1.0, mean[2] / green, ambient]))
