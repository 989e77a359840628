"""MIP-mapped maps (thesis eq. 4.1-4.3, Alg. 4.3), and the trilinear lookup `mc` uses too.

The chain is built as glGenerateMipmap does for a power-of-two texture: each level the 2x2 box
average of the one below, down to 1x1. A lookup is GL_LINEAR_MIPMAP_LINEAR: bilinear within the two
levels around the fractional level of detail, clamped to the edge, and linear between them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import ndimage

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_st_to_pixel, direction_to_anglemap_st
from arsim.core.errors import ArsimError


def mip_chain(image: np.ndarray) -> list[np.ndarray]:
    """Levels 0..log2(N) of a power-of-two N x N image (float64), level 0 the image itself."""
    n = image.shape[0]
    if n < 1 or n & (n - 1):
        raise ArsimError(f"MIP-mapping needs a power-of-two size, got {n}; use --size 128, 256, 512, ...")
    levels = [np.asarray(image, dtype=np.float64)]
    while levels[-1].shape[0] > 1:
        a = levels[-1]
        levels.append(0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2]))
    return levels


def _bilinear_level(level: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    coords = np.stack([rows, cols])
    return np.stack([ndimage.map_coordinates(level[..., c], coords, order=1, mode="nearest", prefilter=False)
                     for c in range(level.shape[2])], axis=-1)


def sample_trilinear(chain: list[np.ndarray], st: np.ndarray, lod: np.ndarray | float) -> np.ndarray:
    """textureLod(chain, st, lod) for texture coordinates (K, 2) and levels of detail (K,) or scalar."""
    st = np.asarray(st, dtype=np.float64)
    lod = np.clip(np.broadcast_to(np.asarray(lod, dtype=np.float64), st.shape[:1]), 0.0, len(chain) - 1)
    lower = np.floor(lod).astype(int)
    frac = lod - lower
    out = np.zeros(st.shape[:1] + (chain[0].shape[2],))
    for level in np.unique(lower):
        for lv, weight in ((level, 1.0 - frac), (min(level + 1, len(chain) - 1), frac)):
            sel = lower == level
            w = weight[sel]
            if not np.any(w > 0):
                continue
            rows, cols = anglemap_st_to_pixel(st[sel], chain[lv].shape[0])
            out[sel] += w[:, None] * _bilinear_level(chain[lv], rows, cols)
    return out


def mipmap_level(exponent: float, n: int) -> float:
    """Eq. 4.1-4.3: the 4x4 level for the irradiance map (s = 1), else l_max - log2(min(max(s/2, 4), N))."""
    l_max = np.log2(n)
    if exponent == 1:
        return float(l_max - 2)
    return float(l_max - np.log2(min(max(exponent / 2.0, 4.0), n)))


def mipmap_maps(env: np.ndarray, exponents: Sequence[float]) -> np.ndarray:
    """Maps (E, N, N, 3) float32: every texel looks the environment up at its own direction, at the
    level eq. 4.2/4.3 give for the exponent (Alg. 4.3 does the same per fragment)."""
    n = env.shape[0]
    chain = mip_chain(env)
    inside = anglemap_disk_mask(n)
    st = direction_to_anglemap_st(anglemap_directions(n)[inside])
    maps = np.zeros((len(exponents), n, n, 3), dtype=np.float32)
    for k, s in enumerate(exponents):
        maps[k][inside] = sample_trilinear(chain, st, mipmap_level(s, n))
    return maps
