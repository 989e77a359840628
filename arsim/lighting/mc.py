"""`mc`: Monte Carlo importance sampling with filtered samples (Colbert and Krivanek, GPU Gems 3 ch. 20),
the bridge between `mipmap` and `accurate` that thesis section 6.2.3 proposes.

For an output direction d, K directions w_k are drawn with density p(w) = (s+1)/(2 pi) cos^s(theta)
around d, the normalised Phong lobe itself, so the lobe average is simply the mean of the radiance
seen in those directions. As in CK07 the K points are one Hammersley set, the same for every texel;
each texel turns it about d by its own hashed angle (texel_turns), so neighbours' errors are unrelated.
Each sample is read from the MIP chain at the level whose texels cover the solid angle the sample
stands for, lod = max(0.5 log2(Omega_s / Omega_p) + LOD_BIAS, 0) with
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

CHUNK_SAMPLES = 8192 * 64  # NumPy path: samples at once, texels per chunk x samples per texel
BYTES_PER_SAMPLE = 240  # NumPy path: the chunk's arrays (uniforms, directions, pdf, st, lod, RGB) per sample
MAX_CHUNK_BYTES = 1 << 30  # one texel's samples must fit in this (the compiled path needs ~100 bytes a sample)


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


def _splitmix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser on uint64 (wrapping arithmetic): a counter-based hash, so any texel's
    random numbers come without drawing the ones before it."""
    x = x + np.uint64(0x9E3779B97F4A7C15)
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def texel_turns(seed: int, exponent: float, texels: np.ndarray) -> np.ndarray:
    """Each texel's turn of the pattern about its direction, in [0, 2 pi): a hash of (seed, exponent,
    flat texel index), so a map is the same whether baked alone, with other exponents or in tiles."""
    with np.errstate(over="ignore"):
        key = _splitmix64(np.uint64(seed) ^ _splitmix64(np.array([np.float64(exponent).view(np.uint64)])))[0]
        bits = _splitmix64(key + np.asarray(texels, dtype=np.uint64))
    return 2.0 * np.pi * ((bits >> np.uint64(11)).astype(np.float64) * 2.0**-53)


def hammersley(samples: int) -> tuple[np.ndarray, np.ndarray]:
    """The Hammersley set of `samples` points (u1, u2): u1 = (j + 1/2) / S, u2 the base-2 radical inverse
    of j. CK07 use it so that few samples cover the lobe evenly; with u1 centred in its stratum no
    sample sits exactly on the lobe's axis or its horizon."""
    j = np.arange(samples, dtype=np.uint64)
    rev = np.zeros(samples, dtype=np.uint64)
    for bit in range(32):
        rev |= ((j >> np.uint64(bit)) & np.uint64(1)) << np.uint64(31 - bit)
    return (np.arange(samples) + 0.5) / samples, rev.astype(np.float64) * 2.0**-32


def pattern_tables(exponents: Sequence[float], samples: int, texel_solid_angle: float):
    """Per exponent and pattern sample (E, S): cos theta, sin theta cos phi, sin theta sin phi, and the
    level of detail 0.5 log2(Omega_s / texel_solid_angle) + LOD_BIAS, which the sinc of where the
    sample lands then lowers by 0.5 log2 sinc (the lookup's Omega_p)."""
    u1, u2 = hammersley(samples)
    phi = 2.0 * np.pi * u2
    s = np.asarray(exponents, dtype=np.float64)[:, None]
    cos_t = u1 ** (1.0 / (s + 1.0))
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
    pdf = (s + 1.0) / (2.0 * np.pi) * cos_t**s
    lod_base = 0.5 * np.log2(1.0 / (samples * pdf) / texel_solid_angle) + LOD_BIAS
    return cos_t, sin_t * np.cos(phi), sin_t * np.sin(phi), lod_base


def bordered_chain(chain: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The chain as one contiguous float32 RGBA array (a texel is one 16-byte read), each level with a
    one-texel border copied from its edge (clamp-to-edge without clamping); offsets (in texels) and sizes."""
    levels = [np.pad(level[..., :3], ((1, 1), (1, 1), (0, 0)), mode="edge") for level in chain]
    flat = np.concatenate([np.pad(level, ((0, 0), (0, 0), (0, 1))).reshape(-1) for level in levels]).astype(np.float32)
    sizes = np.array([level.shape[0] for level in chain], dtype=np.int64)
    offsets = np.r_[0, np.cumsum((sizes + 2) ** 2)[:-1]].astype(np.int64)
    return flat, offsets, sizes


def mc_maps(env: np.ndarray, exponents: Sequence[float], samples: int = 64, seed: int = 0,
            filtered: bool = True, compiled: bool = True) -> np.ndarray:
    """Maps (E, N, N, 3) float32 from `samples` importance samples per texel (filtered or not): the
    Hammersley set, turned about each texel's direction by texel_turns.
    compiled: all exponents in one pass of mc_kernel over a float32 chain; False: NumPy, float64."""
    check_samples(samples)
    n = env.shape[0]
    chain = mip_chain(extend_beyond_rim(env))
    inside = anglemap_disk_mask(n)
    texels = np.flatnonzero(inside)
    dirs = anglemap_directions(n)[inside]
    maps = np.zeros((len(exponents), n, n, 3), dtype=np.float32)
    texel_solid_angle = (2.0 * np.pi / n) ** 2
    turns = np.stack([texel_turns(seed, s, texels) for s in exponents])
    if compiled:
        flat, offsets, sizes = bordered_chain(chain)
        cos_t, along_t, along_b, lod_base = pattern_tables(exponents, samples, texel_solid_angle)
        values = mc_values(dirs, turns, cos_t, along_t, along_b, lod_base, flat, offsets, sizes, filtered)
        maps[:, inside] = values
        return maps
    u1, u2 = hammersley(samples)
    for k, s in enumerate(exponents):
        values = np.empty((len(dirs), 3))
        chunk = max(1, CHUNK_SAMPLES // samples)  # memory bounded whatever the sample count
        for start in range(0, len(dirs), chunk):
            d = dirs[start:start + chunk]
            turn = turns[k, start:start + chunk, None] / (2.0 * np.pi)
            w, pdf = sample_phong_lobe(d, s, np.broadcast_to(u1, (len(d), samples)), u2 + turn)
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
