"""The accurate maps (thesis Alg. 4.1/4.2) and the bounds optimisation (section 6.2.2), in NumPy.

For every output texel d of the disk: M_s(d) = sum_i L_i max(0, d.w_i)^s W_i / sum_i max(0, d.w_i)^s W_i,
summed over every input texel i of the disk with its solid angle W_i (README: Conventions), accumulated
in float64. This is the reference all other methods are measured against. The sums use elementwise
products and row reductions (no BLAS), so a texel's value does not depend on which other texels are
computed with it: a tiled bake equals an untiled one bit for bit.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles
from arsim.core.errors import ArsimError

# Output texels are computed in squares of BLOCK x BLOCK: spatially close, so the bounds optimisation
# finds few candidates, and small enough that the (B x M) temporaries stay within a few hundred MB.
BLOCK = 8
DEFAULT_BOUNDS_THRESHOLD = 0.03


@dataclass(frozen=True)
class Tile:
    """A square of output texels: rows row0..row0+size-1, cols col0..col0+size-1. In the thesis's
    terms (table 4.1): tileOffset = (col0 / N, 1 - (row0 + size) / N), tileScale = size / N."""

    row0: int
    col0: int
    size: int


def tiles(n: int, size: int) -> Iterator[Tile]:
    """The tiles of an N x N map, row by row from the top, as the thesis bakes them over frames."""
    for r in range(0, n, size):
        for c in range(0, n, size):
            yield Tile(r, c, size)


@dataclass(frozen=True)
class _Probe:
    """The input texels of the disk: directions, and (L_r W, L_g W, L_b W, W) with W the solid angle."""

    directions: np.ndarray  # (M, 3)
    weighted: np.ndarray  # (M, 4)

    @classmethod
    def of(cls, env: np.ndarray) -> _Probe:
        n = env.shape[0]
        inside = anglemap_disk_mask(n)
        w = anglemap_solid_angles(n)[inside]
        radiance = env[inside].astype(np.float64)
        return cls(anglemap_directions(n)[inside], np.concatenate([radiance * w[:, None], w[:, None]], axis=1))


def _lobe_sums(out_dirs: np.ndarray, dirs: np.ndarray, weighted: np.ndarray, exponents: Sequence[float],
               threshold: float | None = None) -> np.ndarray:
    """(B, E, 4): per output direction and exponent, sum_i f_i (L_i W_i, W_i) with f_i = max(0, d.w_i)^s,
    and f_i = 0 where it is below the threshold (bounds optimisation)."""
    cos = out_dirs[:, 0:1] * dirs[:, 0] + out_dirs[:, 1:2] * dirs[:, 1] + out_dirs[:, 2:3] * dirs[:, 2]
    np.maximum(cos, 0.0, out=cos)
    with np.errstate(divide="ignore"):
        log_cos = np.log(cos)
    sums = np.empty((out_dirs.shape[0], len(exponents), 4))
    for k, s in enumerate(exponents):
        f = cos if s == 1 else np.exp(s * log_cos)
        if threshold is not None:
            f = np.where(f >= threshold, f, 0.0)
        sums[:, k] = np.einsum("bm,mc->bc", f, weighted)  # C loops, row by row: no BLAS blocking
    return sums


# The largest Phong exponent taken: at 1e6 the lobe is 0.06 degrees wide, far below a texel of any map
# arsim bakes (16384² angle maps: 0.02 degrees a texel is the finest), so larger ones are the same mirror
# and only overflow the lobe's normalisation.
MAX_EXPONENT = 1e6


def check_inputs(env: np.ndarray, exponents: Sequence[float]) -> None:
    """Refuse what no method can work with: a non-square image, NaN/Inf texels, exponents <= 0."""
    if env.ndim != 3 or env.shape[0] != env.shape[1] or env.shape[2] < 3:
        raise ArsimError(f"the environment must be an N x N RGB angle map, got shape {env.shape}")
    if not np.isfinite(env).all():
        raise ArsimError("the environment has NaN or Inf texels; replace them first (arsim convert --nan zero)")
    if len(exponents) == 0:
        raise ArsimError("no Phong exponents given; give at least one, e.g. --spec 1,10,80")
    for s in exponents:
        if not (isinstance(s, (int, float)) and np.isfinite(s) and 0 < s <= MAX_EXPONENT):
            raise ArsimError(f"Phong exponent {s} is not allowed: exponents must be positive numbers up to {MAX_EXPONENT:g}")


def _block_values(block: np.ndarray, probe: _Probe, exponents: Sequence[float], threshold: float | None) -> np.ndarray:
    """(B, E, 3) lobe averages for a block of nearby output directions."""
    if threshold is None:
        sums = _lobe_sums(block, probe.directions, probe.weighted, exponents)
    else:
        # Candidates: input texels within the cone of half-angle acos(threshold^(1/s)) around any
        # direction of the block. The cone lives on the sphere, so it is right at the rim too, where
        # the thesis's square region in texture space misses part of the lobe.
        centre = block.mean(axis=0)
        centre /= np.linalg.norm(centre)
        spread = float(np.arccos(np.clip(block @ centre, -1.0, 1.0)).max())
        to_centre = probe.directions @ centre
        sums = np.empty((len(block), len(exponents), 4))
        for k, s in enumerate(exponents):
            cone = float(np.arccos(threshold ** (1.0 / s)))
            near = np.flatnonzero(to_centre >= np.cos(min(np.pi, cone + spread)))
            sums[:, k] = _lobe_sums(block, probe.directions[near], probe.weighted[near], [s], threshold)[:, 0]
    den = sums[..., 3:]
    return np.divide(sums[..., :3], den, out=np.zeros_like(sums[..., :3]), where=den > 0)


def lobe_average_at(env: np.ndarray, exponents: Sequence[float], directions: np.ndarray,
                    bounds_threshold: float | None = None) -> np.ndarray:
    """M_s at given unit directions (K, 3), as (K, E, 3) float64: the accurate sum (or bounded)."""
    check_inputs(env, exponents)
    probe = _Probe.of(env)
    directions = np.asarray(directions, dtype=np.float64)
    out = np.empty((len(directions), len(exponents), 3))
    step = BLOCK * BLOCK
    for start in range(0, len(directions), step):
        out[start:start + step] = _block_values(directions[start:start + step], probe, exponents, bounds_threshold)
    return out


def accurate_maps(env: np.ndarray, exponents: Sequence[float], tile: Tile | None = None,
                  bounds_threshold: float | None = None, progress=None) -> np.ndarray:
    """Maps (E, N, N, 3) float32 for the exponents, of the whole map or one tile (other texels 0).

    bounds_threshold: drop lobe values below it (the bounds method); None sums every texel.
    progress: optional callable(done_fraction) for long bakes."""
    check_inputs(env, exponents)
    n = env.shape[0]
    probe = _Probe.of(env)
    inside = anglemap_disk_mask(n)
    directions = anglemap_directions(n)
    maps = np.zeros((len(exponents), n, n, 3), dtype=np.float32)
    region = tile or Tile(0, 0, n)
    rows = range(region.row0, min(n, region.row0 + region.size), BLOCK)
    cols = range(region.col0, min(n, region.col0 + region.size), BLOCK)
    r_end, c_end = min(n, region.row0 + region.size), min(n, region.col0 + region.size)
    done, total = 0, len(rows) * len(cols)
    for r in rows:
        for c in cols:
            rr, cc = slice(r, min(r + BLOCK, r_end)), slice(c, min(c + BLOCK, c_end))
            mask = inside[rr, cc]
            if mask.any():
                values = _block_values(directions[rr, cc][mask], probe, exponents, bounds_threshold)
                sub = maps[:, rr, cc]
                sub[:, mask] = values.transpose(1, 0, 2)
                maps[:, rr, cc] = sub
            done += 1
            if progress is not None:
                progress(done / total)
    return maps
