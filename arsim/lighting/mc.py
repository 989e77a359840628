"""`mc`: Monte Carlo importance sampling with filtered samples (Colbert and Krivanek, GPU Gems 3 ch. 20),
the bridge between `mipmap` and `accurate` that thesis section 6.2.3 proposes.

For an output direction d, K directions w_k are drawn with density p(w) = (s+1)/(2 pi) cos^s(theta)
around d, the normalised Phong lobe itself, so the lobe average is simply the mean of the radiance
seen in those directions. Each sample is read from the MIP chain at the level whose texels cover the
solid angle the sample stands for, lod = max(0.5 log2(Omega_s / Omega_p) + LOD_BIAS, 0) with
Omega_s = 1 / (K p) and Omega_p the level-0 texel's solid angle there; that turns the noise of few
samples into blur. The chain is built from the probe extended past the rim (core.resample), so that
coarse levels near -z do not average in the black outside the disk. Deterministic for a given seed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_radius, direction_to_anglemap_st
from arsim.core.errors import ArsimError
from arsim.core.resample import extend_beyond_rim
from arsim.lighting.mc_kernel import mc_values
from arsim.lighting.mipmap import mip_chain, sample_trilinear

CHUNK_SAMPLES = 8192 * 64  # samples drawn at once: texels per chunk x samples per texel
BYTES_PER_SAMPLE = 240  # the chunk's arrays (uniforms, directions, pdf, st, lod, gathered RGB) per sample
MAX_CHUNK_BYTES = 1 << 30  # one texel's samples must fit in this


def check_samples(samples: int) -> None:
    """Refuse a sample count whose single texel's arrays alone would pass MAX_CHUNK_BYTES."""
    if samples * BYTES_PER_SAMPLE > MAX_CHUNK_BYTES:
        raise ArsimError(f"sample count {samples} needs {samples * BYTES_PER_SAMPLE / 2**30:.1f} GiB per texel; "
                         f"give at most {MAX_CHUNK_BYTES // BYTES_PER_SAMPLE}")


# CK07 add 1 to the level of detail; on angle maps, whose coarse levels mix distant directions, that
# over-blurs: on courtyard and city at 64², bias 0 gave lower mean error than 1 at every K from 4 to 256.
LOD_BIAS = 0.0


def _orthonormal_frames(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing each direction (K, 3) to a right-handed orthonormal frame."""
    helper = np.where(np.abs(d[:, 2:3]) < 0.9, np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]))
    t = np.cross(helper, d)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(d, t)


def sample_phong_lobe(d: np.ndarray, exponent: float, u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directions (K, S, 3) with density (s+1)/(2 pi) cos^s about d (K, 3), and that density (K, S)."""
    cos_t = u1 ** (1.0 / (exponent + 1.0))
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    phi = 2.0 * np.pi * u2
    t, b = _orthonormal_frames(d)
    w = (sin_t * np.cos(phi))[..., None] * t[:, None] + (sin_t * np.sin(phi))[..., None] * b[:, None] + cos_t[..., None] * d[:, None]
    return w, (exponent + 1.0) / (2.0 * np.pi) * cos_t**exponent


def mc_maps(env: np.ndarray, exponents: Sequence[float], samples: int = 64, seed: int = 0,
            filtered: bool = True, compiled: bool = True) -> np.ndarray:
    """Maps (E, N, N, 3) float32 from `samples` importance samples per texel (filtered or not).
    compiled: the samples' arithmetic and lookups in mc_kernel (same uniforms, same sums); False: NumPy."""
    check_samples(samples)
    n = env.shape[0]
    chain = mip_chain(extend_beyond_rim(env))
    inside = anglemap_disk_mask(n)
    dirs = anglemap_directions(n)[inside]
    maps = np.zeros((len(exponents), n, n, 3), dtype=np.float32)
    texel_solid_angle = (2.0 * np.pi / n) ** 2
    if compiled:
        flat = np.concatenate([level[..., :3].ravel() for level in chain])
        sizes = np.array([level.shape[0] for level in chain], dtype=np.int64)
        offsets = np.r_[0, np.cumsum(sizes * sizes * 3)[:-1]].astype(np.int64)
    for k, s in enumerate(exponents):
        # One stream per (seed, exponent): a map is the same whether baked alone or with others.
        rng = np.random.default_rng([seed, int(np.float64(s).view(np.uint64))])
        values = np.empty((len(dirs), 3))
        chunk = max(1, CHUNK_SAMPLES // samples)  # memory bounded whatever the sample count
        for start in range(0, len(dirs), chunk):
            d = dirs[start:start + chunk]
            u1, u2 = rng.random((2, len(d), samples))
            if compiled:
                values[start:start + len(d)] = mc_values(d, u1, u2, float(s), flat, offsets, sizes, texel_solid_angle,
                                                         LOD_BIAS, filtered)
                continue
            w, pdf = sample_phong_lobe(d, s, u1, u2)
            st = direction_to_anglemap_st(w.reshape(-1, 3))
            if filtered:
                omega_p = texel_solid_angle * np.maximum(np.sinc(anglemap_radius(st)), 1e-6)
                omega_s = 1.0 / (samples * pdf.reshape(-1))
                lod = np.maximum(0.5 * np.log2(omega_s / omega_p) + LOD_BIAS, 0.0)
            else:
                lod = 0.0
            values[start:start + len(d)] = sample_trilinear(chain, st, lod).reshape(len(d), samples, 3).mean(axis=1)
        maps[k][inside] = values
    return maps
