"""GGX prefiltered cube maps and the BRDF lookup table of the split-sum approximation (Karis 2013, "Real Shading
in Unreal Engine 4"), as Filament's cmgen and the glTF Sample Viewer make them (README: Maps for engines).

The specular part of image-based lighting, int L(l) f(v, l) (n.l) dl, is split into two factors:
- the prefiltered radiance: the radiance averaged over the GGX lobe about a direction r, taking n = v = r
  (the lobe's shape at normal incidence), weighted by n.l; mip level p of a chain of P holds perceptual
  roughness p / (P - 1) (alpha = roughness^2), level 0 the radiance itself;
- the BRDF's integral under white light, F0 * scale + bias with scale = int (1 - Fc) f/F (n.l) dl and
  bias = int Fc f/F (n.l) dl, Fc = (1 - v.h)^5 (Schlick), as a table over (n.v, roughness).
f is the GGX (Trowbridge-Reitz) distribution with the height-correlated Smith visibility (Heitz 2014), as
Filament and the glTF Sample Viewer use.

The prefilter draws GGX half vectors by importance (a Hammersley set, the same for every texel, turned into
its frame) and reads each sample from the source's MIP chain at the level whose texels cover the solid angle
the sample stands for (filtered importance sampling: Colbert and Krivanek, GPU Gems 3 ch. 20; Karis 2013),
so that a few dozen samples give a smooth lobe. All in NumPy, vectorised over texels and samples.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from arsim.core.conventions import cube_directions, cube_face_st
from arsim.core.errors import ArsimError

SMALLEST_LEVEL = 4  # the chain's smallest level, 4 x 4 per face: roughness 1 needs no more
PREFILTER_SAMPLES = 64  # GGX samples per texel, filtered: enough for a smooth lobe at every roughness
LUT_SIZE = 128  # the BRDF table: LUT_SIZE x LUT_SIZE (n.v across, roughness down)
LUT_SAMPLES = 2048  # within 0.1 % of a quadrature reference for n.v >= 0.25, 1 % down to n.v = 0.02 (README)
LOD_BIAS = 1.0  # Karis's and GPU Gems 3's +1: a sample reads a level one coarser than its solid angle alone asks


def level_count(size: int) -> int:
    """The GGX chain's levels for a face of `size`: down to SMALLEST_LEVEL x SMALLEST_LEVEL (at least 2)."""
    return max(2, int(np.log2(size)) - int(np.log2(SMALLEST_LEVEL)) + 1)


def level_roughness(levels: int) -> np.ndarray:
    """Perceptual roughness of each level: p / (levels - 1)."""
    return np.arange(levels) / (levels - 1)


def hammersley(count: int) -> tuple[np.ndarray, np.ndarray]:
    """The Hammersley point set in [0, 1)^2: (i + 0.5) / count and the radical inverse of i in base 2."""
    i = np.arange(count, dtype=np.uint64)
    bits = np.zeros(count, dtype=np.uint64)
    for b in range(32):
        bits |= ((i >> np.uint64(b)) & np.uint64(1)) << np.uint64(31 - b)
    return (np.arange(count) + 0.5) / count, bits.astype(np.float64) / 2.0**32


def ggx_half_vectors(alpha: float, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """(K, 3) half vectors about +z with density D(h) (n.h) (the GGX distribution's importance sampling)."""
    a2 = alpha * alpha
    cos_t = np.sqrt((1.0 - u1) / (1.0 + (a2 - 1.0) * u1))
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * np.pi * u2
    return np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=-1)


def ggx_distribution(n_dot_h: np.ndarray, alpha: float) -> np.ndarray:
    """D(h) = alpha^2 / (pi ((n.h)^2 (alpha^2 - 1) + 1)^2)."""
    a2 = alpha * alpha
    return a2 / (np.pi * (n_dot_h * n_dot_h * (a2 - 1.0) + 1.0) ** 2)


# ---------------------------------------------------------------------------------------------------
# Cube maps: MIP chain and filtered lookups


def cube_mip_chain(cube: np.ndarray) -> list[np.ndarray]:
    """Levels of a (6, N, N, C) cube map down to 1 x 1, each the 2 x 2 box average of the one before (float64)."""
    levels = [np.asarray(cube, dtype=np.float64)]
    while levels[-1].shape[1] > 1:
        a = levels[-1]
        levels.append(0.25 * (a[:, 0::2, 0::2] + a[:, 1::2, 0::2] + a[:, 0::2, 1::2] + a[:, 1::2, 1::2]))
    return levels


def sample_cube(level: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Bilinear radiance (K, C) of one cube level (6, N, N, C) in unit directions (K, 3); within a face, clamped
    at its edges (a seam's texels blend with their own face only)."""
    n = level.shape[1]
    face, s, t = cube_face_st(directions)
    col = np.clip((s + 1.0) * 0.5 * n - 0.5, 0.0, n - 1.0)
    row = np.clip((t + 1.0) * 0.5 * n - 0.5, 0.0, n - 1.0)
    c0, r0 = np.floor(col).astype(int), np.floor(row).astype(int)
    c1, r1 = np.minimum(c0 + 1, n - 1), np.minimum(r0 + 1, n - 1)
    fc, fr = (col - c0)[:, None], (row - r0)[:, None]
    return ((1 - fr) * ((1 - fc) * level[face, r0, c0] + fc * level[face, r0, c1])
            + fr * ((1 - fc) * level[face, r1, c0] + fc * level[face, r1, c1]))


def sample_cube_lod(chain: Sequence[np.ndarray], directions: np.ndarray, lod: np.ndarray) -> np.ndarray:
    """textureLod on a cube map's chain: bilinear in the two levels around each fractional lod (K,), linear
    between them (lod clamped to the chain)."""
    lod = np.clip(np.asarray(lod, dtype=np.float64), 0.0, len(chain) - 1)
    lower = np.floor(lod).astype(int)
    frac = (lod - lower)[:, None]
    out = np.zeros((len(directions), chain[0].shape[-1]))
    for p in np.unique(lower):
        sel = lower == p
        d, f = directions[sel], frac[sel]
        value = (1.0 - f) * sample_cube(chain[p], d)
        if p + 1 < len(chain):
            value += f * sample_cube(chain[p + 1], d)
        out[sel] = value
    return out


def _frames(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing each direction (K, 3) to an orthonormal frame."""
    helper = np.where(np.abs(n[:, 1:2]) < 0.999, np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0]))
    t = np.cross(helper, n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def prefilter_level(chain: Sequence[np.ndarray], size: int, roughness: float, samples: int = PREFILTER_SAMPLES) -> np.ndarray:
    """(6, size, size, C): the radiance of the chain (level 0 the source) averaged over the GGX lobe of this
    perceptual roughness about each texel's direction, n = v = r, weighted by n.l (Karis 2013's prefilter)."""
    alpha = roughness * roughness
    u1, u2 = hammersley(samples)
    h_local = ggx_half_vectors(alpha, u1, u2)  # (K, 3) about +z
    pdf_l = ggx_distribution(h_local[:, 2], alpha) / 4.0  # density of l = reflect(-v, h) with v = n: D (n.h) / (4 v.h)
    source = chain[0].shape[1]
    omega_p = 4.0 * np.pi / (6.0 * source * source)  # a source texel's solid angle (the face's mean)
    omega_s = 1.0 / (samples * np.maximum(pdf_l, 1e-300))
    lod = np.maximum(0.5 * np.log2(omega_s / omega_p) + LOD_BIAS, 0.0)
    out = np.empty((6, size, size, chain[0].shape[-1]))
    for face, normals in enumerate(cube_directions(size)):
        n = normals.reshape(-1, 3)
        t, b = _frames(n)
        h = h_local[None, :, 0:1] * t[:, None] + h_local[None, :, 1:2] * b[:, None] + h_local[None, :, 2:3] * n[:, None]
        n_dot_h = h_local[None, :, 2]
        light = 2.0 * n_dot_h[..., None] * h - n[:, None]  # reflect(-n, h)
        n_dot_l = np.einsum("pkj,pj->pk", light, n)
        weight = np.maximum(n_dot_l, 0.0)
        values = sample_cube_lod(chain, light.reshape(-1, 3), np.broadcast_to(lod, n_dot_l.shape).reshape(-1))
        values = values.reshape(n_dot_l.shape + (values.shape[-1],))
        out[face] = ((values * weight[..., None]).sum(axis=1) / np.maximum(weight.sum(axis=1), 1e-300)[:, None]).reshape(size, size, -1)
    return out


def prefilter_ggx(cube: np.ndarray, levels: int | None = None, samples: int = PREFILTER_SAMPLES) -> list[np.ndarray]:
    """The GGX chain of a (6, N, N, C) radiance cube: level p (N >> p per face) at perceptual roughness
    p / (levels - 1); level 0 is the cube itself (roughness 0: a mirror)."""
    size = cube.shape[1]
    if cube.shape[0] != 6 or cube.shape[2] != size or size & (size - 1):
        raise ArsimError(f"a GGX chain needs a cube map of 6 square power-of-two faces, got {cube.shape[:3]}")
    levels = level_count(size) if levels is None else levels
    if not 2 <= levels <= int(np.log2(size)) + 1:
        raise ArsimError(f"{levels} GGX levels for {size} x {size} faces; give 2 to {int(np.log2(size)) + 1}")
    chain = cube_mip_chain(cube)
    roughness = level_roughness(levels)
    return [chain[0]] + [prefilter_level(chain, size >> p, float(roughness[p]), samples) for p in range(1, levels)]


# ---------------------------------------------------------------------------------------------------
# The BRDF's split-sum table


def split_sum(n_dot_v: np.ndarray, roughness: np.ndarray, samples: int = LUT_SAMPLES) -> np.ndarray:
    """(..., 2): (scale, bias) of the split sum at each (n.v, perceptual roughness): the integral of the GGX
    specular BRDF times n.l over l with the Fresnel term replaced by (1 - Fc) and by Fc, estimated with GGX
    importance sampling on a Hammersley set (Karis 2013): for h drawn with density D (n.h), the sample's weight
    is f (n.l) / p(l) = 4 Vis (n.l) (v.h) / (n.h)."""
    n_dot_v, roughness = np.broadcast_arrays(np.asarray(n_dot_v, dtype=np.float64), np.asarray(roughness, dtype=np.float64))
    shape = n_dot_v.shape
    nv, rough = n_dot_v.reshape(-1), roughness.reshape(-1)
    u1, u2 = hammersley(samples)
    out = np.zeros((len(nv), 2))
    for r in np.unique(rough):
        sel = rough == r
        alpha = float(r) ** 2
        a2 = alpha * alpha
        h = ggx_half_vectors(alpha, u1, u2)  # (K, 3) about n = +z; v = (sqrt(1 - (n.v)^2), 0, n.v)
        cos_v = nv[sel][:, None]
        v_dot_h = np.sqrt(np.maximum(0.0, 1.0 - cos_v * cos_v)) * h[None, :, 0] + cos_v * h[None, :, 2]
        n_dot_l = 2.0 * v_dot_h * h[None, :, 2] - cos_v
        nl = np.maximum(n_dot_l, 0.0)
        # 4 Vis (n.l) (v.h) / (n.h), Vis = 0.5 / ((n.l) sqrt((n.v)^2 (1 - a2) + a2) + (n.v) sqrt((n.l)^2 (1 - a2) + a2)):
        # the height-correlated Smith visibility G / (4 (n.v) (n.l)) of GGX (Heitz 2014, eq. 99)
        denominator = nl * np.sqrt(cos_v * cos_v * (1.0 - a2) + a2) + cos_v * np.sqrt(nl * nl * (1.0 - a2) + a2)
        weight = np.where((n_dot_l > 0) & (v_dot_h > 0), 2.0 * nl * v_dot_h / (h[None, :, 2] * np.maximum(denominator, 1e-300)), 0.0)
        fc = (1.0 - np.clip(v_dot_h, 0.0, 1.0)) ** 5
        total, bias = weight.sum(axis=1), (fc * weight).sum(axis=1)
        out[sel, 0] = (total - bias) / samples
        out[sel, 1] = bias / samples
    return out.reshape(shape + (2,))


def brdf_lut(size: int = LUT_SIZE, samples: int = LUT_SAMPLES) -> np.ndarray:
    """(size, size, 2) the split sum's (scale, bias): column c at n.v = (c + 0.5) / size, row r at perceptual
    roughness (r + 0.5) / size, row 0 first (roughness near 0). The same for every light: computed once a process."""
    return _brdf_lut(size, samples).copy()


@functools.cache
def _brdf_lut(size: int, samples: int) -> np.ndarray:
    centres = (np.arange(size) + 0.5) / size
    roughness, n_dot_v = np.meshgrid(centres, centres, indexing="ij")
    return split_sum(n_dot_v, roughness, samples)
