"""`mc`: Monte Carlo importance sampling with filtered samples (Colbert and Krivanek, GPU Gems 3 ch. 20),
the bridge between `mipmap` and `accurate` that thesis section 6.2.3 proposes.

For an output direction d, K directions w_k are drawn with density p(w) = (s+1)/(2 pi) cos^s(theta)
around d, the normalised Phong lobe itself, so the lobe average is simply the mean of the radiance
seen in those directions. As in CK07 the K points are one Hammersley set, the same for every point;
each point turns it about d by its own hashed angle (texel_turns), so neighbouring points' errors are unrelated.
Each sample is read from the MIP chain at the level whose texels cover the solid angle the sample
stands for, lod = max(0.5 log2(Omega_s / Omega_p) + LOD_BIAS, 0) with
Omega_s = 1 / (K p) and Omega_p the level-0 texel's solid angle there; that turns the noise of few
samples into blur. The chain is built from the probe extended past the rim (core.resample), so that
coarse levels near -z do not average in the black outside the disk. Deterministic for a given seed.

A lobe's map is smooth on the scale of the lobe, so each is estimated at the points of a theta-phi grid
as fine as the lobe needs (lobe_grid: two points a band in theta of the bands its zonal coefficients
carry above GRID_TRUNCATION, as `sht` sizes its syntheses' grids) and read at the texels bicubically, as
`sht` reads its grids; a lobe whose grid would have more points than the map has texels (narrow lobes on
small maps) is estimated at the texels themselves. A 512² map has 206,000 texels; the grids of s = 10 and
s = 1280 have 1,000 and 142,000 points (README: `mc` and the speed of `sh` over its orders).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_radius, direction_to_anglemap_st
from arsim.core.errors import ArsimError
from arsim.core.resample import extend_beyond_rim
from arsim.lighting.mc_kernel import mc_values
from arsim.lighting.mipmap import mip_chain, sample_trilinear
from arsim.lighting.sh_kernel import cubic_lookup_into, rgba_grid
from arsim.lighting.sht import bands_above, grid_coordinates, grid_directions

CHUNK_SAMPLES = 8192 * 64  # NumPy path: samples at once, texels per chunk x samples per texel
BYTES_PER_SAMPLE = 240  # NumPy path: the chunk's arrays (uniforms, directions, pdf, st, lod, RGB) per sample
MAX_CHUNK_BYTES = 1 << 30  # one texel's samples must fit in this (the compiled path needs ~100 bytes a sample)


def check_samples(samples: int) -> None:
    """Refuse a sample count whose single texel's arrays alone would pass MAX_CHUNK_BYTES."""
    if samples * BYTES_PER_SAMPLE > MAX_CHUNK_BYTES:
        raise ArsimError(f"sample count {samples} needs {samples * BYTES_PER_SAMPLE / 2**30:.1f} GiB per texel; "
                         f"give at most {MAX_CHUNK_BYTES // BYTES_PER_SAMPLE}")


# A lobe's grid has GRID_SAMPLES_PER_BAND points a band in theta of the bands whose zonal coefficient is at
# least GRID_TRUNCATION of band 0's, and at least one a band of those above TAIL_TRUNCATION: the clamped
# cosines of s = 1 and 2 fall only as a power of l, and their maps' kinks (a bright source's horizon) need it.
# Measured at 512² on the eight bundled probes, reading the exact maps (`sht`'s) through such grids: mean
# error 0.001-0.68 % (worst: studio, s = 10), max 0.02-13 %, where 64 samples leave a mean error of 3-65 %
# and a max of 20-3,600 % (README: `mc` and the speed of `sh` over its orders).
GRID_TRUNCATION = 1e-3
GRID_SAMPLES_PER_BAND = 2
TAIL_TRUNCATION = 1e-5


def lobe_grid(exponent: float, texels: int) -> tuple[int, int] | None:
    """(n_theta, n_phi) of the Clenshaw-Curtis grid (sht.grid_directions) a lobe's map is estimated on, or
    None where that grid would have more points than the map's `texels` (estimated at the texels)."""
    s = float(exponent)
    n_theta = max(GRID_SAMPLES_PER_BAND * bands_above(s, GRID_TRUNCATION), bands_above(s, TAIL_TRUNCATION)) + 1
    n_phi = 2 * (n_theta - 1)
    return (n_theta, n_phi) if n_theta * n_phi < texels else None


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
    """Each point's turn of the pattern about its direction, in [0, 2 pi): a hash of (seed, exponent, the
    point's flat index: the texel's, or the grid point's where the lobe has a grid), so a map is the same
    whether baked alone, with other exponents or in parts."""
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
    sizes = np.array([level.shape[0] for level in chain], dtype=np.int64)
    offsets = np.r_[0, np.cumsum((sizes + 2) ** 2)[:-1]].astype(np.int64)
    flat = np.zeros(4 * int(np.sum((sizes + 2) ** 2)), dtype=np.float32)
    for level, offset, size in zip(chain, offsets, sizes):  # (written in place: no padded copies)
        bordered = flat[4 * offset:4 * (offset + (size + 2) ** 2)].reshape(size + 2, size + 2, 4)
        bordered[1:-1, 1:-1, :3] = level[..., :3]
        bordered[0, 1:-1, :3], bordered[-1, 1:-1, :3] = level[0, :, :3], level[-1, :, :3]
        bordered[:, 0], bordered[:, -1] = bordered[:, 1], bordered[:, -2]
    return flat, offsets, sizes


def mc_maps(env: np.ndarray, exponents: Sequence[float], samples: int = 64, seed: int = 0,
            filtered: bool = True, compiled: bool = True, grids: bool = True) -> np.ndarray:
    """Maps (E, N, N, 3) float32 from `samples` importance samples per point (filtered or not): the
    Hammersley set, turned about each point's direction by texel_turns, at the points of each lobe's grid
    (lobe_grid) read bicubically at the texels, or at the texels themselves (always where grids is False).
    compiled: each set of points in one pass of mc_kernel over a float32 chain, every exponent estimated
    there at once; False: NumPy, float64 (the same points and lookups)."""
    check_samples(samples)
    n = env.shape[0]
    chain = mip_chain(extend_beyond_rim(env))
    inside = anglemap_disk_mask(n)
    texels = np.flatnonzero(inside)
    maps = np.zeros((len(exponents), n, n, 3), dtype=np.float32)
    texel_solid_angle = (2.0 * np.pi / n) ** 2
    groups = {}  # grid (None: the texels) -> the exponents' indices estimated at its points
    for k, s in enumerate(exponents):
        groups.setdefault(lobe_grid(s, len(texels)) if grids else None, []).append(k)
    if compiled:
        flat, offsets, sizes = bordered_chain(chain)
        tables = pattern_tables(exponents, samples, texel_solid_angle)
    for grid, ks in groups.items():
        dirs, points = ((anglemap_directions(n)[inside], texels) if grid is None else
                        (grid_directions(*grid), np.arange(grid[0] * grid[1])))
        turns = np.stack([texel_turns(seed, exponents[k], points) for k in ks])
        if compiled:
            values = mc_values(dirs, turns, *(table[ks] for table in tables), flat, offsets, sizes, filtered)
        else:
            values = np.stack([_numpy_values(chain, dirs, turn, exponents[k], samples, filtered, texel_solid_angle)
                               for k, turn in zip(ks, turns)])
        for k, v in zip(ks, values):
            if grid is None:
                maps[k][inside] = v
            else:
                values = rgba_grid(*grid)
                values.reshape(-1, 4)[:, :3] = v
                cubic_lookup_into(maps[k].reshape(n * n, 3), texels, values.reshape(-1), *grid, *grid_coordinates(n, *grid),
                                  np.ones(len(texels)))
    return maps


def _numpy_values(chain: list[np.ndarray], dirs: np.ndarray, turns: np.ndarray, exponent: float, samples: int,
                  filtered: bool, texel_solid_angle: float) -> np.ndarray:
    """(K, 3) float64 lobe averages at dirs (K, 3), each pattern turned by turns (K,): mc_values's reference."""
    u1, u2 = hammersley(samples)
    values = np.empty((len(dirs), 3))
    chunk = max(1, CHUNK_SAMPLES // samples)  # memory bounded whatever the sample count
    for start in range(0, len(dirs), chunk):
        d = dirs[start:start + chunk]
        turn = turns[start:start + chunk, None] / (2.0 * np.pi)
        w, pdf = sample_phong_lobe(d, exponent, np.broadcast_to(u1, (len(d), samples)), u2 + turn)
        st = direction_to_anglemap_st(w.reshape(-1, 3))
        if filtered:
            omega_p = texel_solid_angle * np.maximum(np.sinc(anglemap_radius(st)), 1e-6)
            omega_s = 1.0 / (samples * pdf.reshape(-1))
            lod = np.maximum(0.5 * np.log2(omega_s / omega_p) + LOD_BIAS, 0.0)
        else:
            lod = 0.0
        values[start:start + len(d)] = sample_trilinear(chain, st, lod).reshape(len(d), samples, 3).mean(axis=1)
    return values
