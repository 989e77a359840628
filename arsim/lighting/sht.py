"""`sht`: the maps through ducc0's fast spherical-harmonic transforms, and the transforms `sh` and `fast` share.

The maps are convolutions of the sphere with the rotationally symmetric Phong lobe, so in SH they are the
probe's coefficients times the lobe's zonal coefficients kappa_l(s) (eq. 2.31/2.33). Here:

- the coefficients are the exact sums over the source angle map's texels with their solid angles (what
  `accurate` sums), at the source's own resolution, through ducc0's adjoint non-uniform synthesis
  (`adjoint_synthesis_general`: a NUFFT, accurate to EPSILON) -- one transform shared by all exponents;
- the weights' own coefficients (a channel of ones) ride along, so each map is divided by the lobe sum
  of the texel weights as `accurate` divides by sum f W;
- each exponent's map is synthesised at the bandlimit its lobe needs: the first band where kappa_l has
  fallen below TRUNCATION (about sqrt(2 s ln(1/TRUNCATION)) for large s), never below MIN_BANDS, on a
  Clenshaw-Curtis grid fine enough for the lobe (grid_size), from which a bicubic lookup reads the texels;
- from an equirect source (sht_maps_from_source), whose rows are rings of equal latitude about +y, the
  texel sums are a ring-based adjoint transform instead (`adjoint_synthesis_2d` on its own grid), and
  the maps are synthesised in that frame.

Frame and real-SH convention: as sh.py (pole +z, phi = atan2(d_y, -d_x), Condon-Shortley phase, index
l(l+1)+m); ducc0's complex a_lm (healpy's layout, m >= 0) map to them by c_l0 = a_l0,
c_lm = sqrt2 Re a_lm, c_l(-m) = -sqrt2 Im a_lm.
"""

from __future__ import annotations

import functools
import itertools
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import ducc0
import numpy as np

from arsim.core.conventions import (anglemap_directions, anglemap_disk_mask, anglemap_solid_angles,
                                    direction_to_equirect_uv, equirect_directions, equirect_solid_angles)
from arsim.core.resample import detect_layout
from arsim.lighting.phong import phong_zonal_coefficients
from arsim.lighting.sh_kernel import cubic_lookup_into, rgba_grid

_SHT = ducc0.sht.experimental
EPSILON = 1e-12  # the NUFFTs' relative accuracy for `sh` (its coefficients must match the exact texel sums)
FAST_EPSILON = 2e-6  # for `sht`, in single precision: far below its truncation, and about twice as fast
TRUNCATION = 1e-6  # sht: drop bands whose zonal coefficient is below this (1e-4 left 30 % near a bright texel)
GRID_TRUNCATION = 1e-4  # the bands the grid resolves with GRID_SAMPLES_PER_BAND samples
MAX_BANDS_SEARCH = 1024
MIN_BANDS = 48  # the clamped cosine of s = 1 decays only like l^-2.5
GRID_SAMPLES_PER_BAND = 4


def threads() -> int:
    return 0  # ducc0: every hardware thread


def sh_angles(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) of directions in the SH frame: pole +z, phi = atan2(d_y, -d_x) in [0, 2 pi)."""
    d = np.asarray(directions, dtype=np.float64)
    theta = np.arctan2(np.hypot(d[..., 0], d[..., 1]), d[..., 2])
    phi = np.mod(np.arctan2(d[..., 1], -d[..., 0]), 2 * np.pi)
    return theta, phi


@functools.lru_cache(maxsize=4)
def disk_locations(n: int) -> np.ndarray:
    """(M, 2) (theta, phi) of the disk texels of an N x N angle map, row-major (ducc0's `loc`)."""
    theta, phi = sh_angles(anglemap_directions(n)[anglemap_disk_mask(n)])
    loc = np.stack([theta, phi], axis=1)
    loc.setflags(write=False)
    return loc


@functools.lru_cache(maxsize=16)
def _alm_index(lmax: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every ducc0 alm slot (healpy order, m-major): its l, m and the real-SH row l(l+1)+m."""
    m = np.repeat(np.arange(lmax + 1), np.arange(lmax + 1, 0, -1))
    l = np.arange(m.size) - (m * (2 * lmax + 1 - m)) // 2
    out = (l, m, l * (l + 1) + m)
    for a in out:
        a.setflags(write=False)
    return out


def alm_bands(lmax: int) -> np.ndarray:
    """The band l of every ducc0 alm slot of lmax."""
    return _alm_index(lmax)[0]


def real_from_alm(alm: np.ndarray, order: int) -> np.ndarray:
    """Real coefficients (order^2, C) from ducc0's complex alm (C, nalm) of lmax = order-1."""
    l, m, row = _alm_index(order - 1)
    out = np.zeros((order * order, alm.shape[0]))
    zero = m == 0
    out[row[zero]] = alm[:, zero].real.T
    out[row[~zero]] = np.sqrt(2.0) * alm[:, ~zero].real.T
    out[(l * (l + 1) - m)[~zero]] = -np.sqrt(2.0) * alm[:, ~zero].imag.T
    return out


def alm_from_real(coeffs: np.ndarray, order: int) -> np.ndarray:
    """ducc0's complex alm (C, nalm) of lmax = order-1 from real coefficients (>= order^2, C)."""
    l, m, row = _alm_index(order - 1)
    zero = m == 0
    alm = np.zeros((coeffs.shape[1], l.size), dtype=np.complex128)
    alm[:, zero] = coeffs[row[zero]].T
    alm[:, ~zero] = (coeffs[row[~zero]] - 1j * coeffs[(l * (l + 1) - m)[~zero]]).T / np.sqrt(2.0)
    return alm


def zonal_scale(alm: np.ndarray, factors: np.ndarray) -> np.ndarray:
    """alm (C, nalm) times a factor per band l (factors of length lmax+1)."""
    l, _, _ = _alm_index(factors.size - 1)
    return alm * factors[l].astype(alm.real.dtype)


def texel_sums_alm(env: np.ndarray, lmax: int, epsilon: float = EPSILON) -> np.ndarray:
    """ducc0 alm (C, nalm) of sum_i L_i conj(Y_lm(w_i)) W_i over the disk texels of an angle map (N, N, C);
    in single precision where epsilon allows it (ducc0: above 1e-6)."""
    n = env.shape[0]
    dtype = np.float32 if epsilon > 1e-6 else np.float64
    texels = np.asarray(env, dtype=dtype).reshape(n * n, -1)[disk_index(n)]
    weighted = (texels * disk_solid_angles(n).astype(dtype)[:, None]).T
    return adjoint_at(np.ascontiguousarray(weighted), disk_locations(n), lmax, epsilon)


def adjoint_at(planes: np.ndarray, loc: np.ndarray, lmax: int, epsilon: float) -> np.ndarray:
    """ducc0 alm (C, nalm) of sum_i planes[c, i] conj(Y_lm(loc_i)) (ducc0's adjoint non-uniform transform).
    The planes are laid end to end and cut into a run of points per core (work_runs), each run's pieces
    transformed one after another on its own thread, and a plane cut in two summed from its pieces in their
    order: every core busy (three channels on two cores took two rounds of one), and the sums the same
    whatever the threads' timing. ducc0's own threads would share one transform's spreading onto the grid,
    whose sums come in an order that depends on their timing: under load the same input gave different last
    bits."""
    points = planes.shape[1]

    def run(pieces):
        return [_SHT.adjoint_synthesis_general(map=np.ascontiguousarray(planes[c, a:b][None]), spin=0, lmax=lmax,
                                               loc=np.ascontiguousarray(loc[a:b]), epsilon=epsilon, nthreads=1)[0]
                for c, a, b in pieces]

    runs = work_runs(len(planes), points, os.cpu_count() or 1)
    with ThreadPoolExecutor(len(runs)) as pool:  # (joined here: no threads outlive the call)
        results = [result for pieces in pool.map(run, runs) for result in pieces]
    out = np.zeros((len(planes), results[0].size), dtype=results[0].dtype)
    for (c, _, _), result in zip((piece for pieces in runs for piece in pieces), results):
        out[c] += result  # (a plane's pieces in the order of its points)
    return out


def work_runs(planes: int, points: int, workers: int) -> list[list[tuple[int, int, int]]]:
    """`planes` of `points` laid end to end and cut into at most `workers` runs of equal length, each run a list of
    pieces (plane, first point, end): a plane is cut only where a run ends inside it."""
    total = planes * points
    bounds = sorted({total * w // workers for w in range(workers + 1)})
    runs = []
    for a, b in itertools.pairwise(bounds):
        pieces = []
        while a < b:
            plane, start = divmod(a, points)
            end = min(points, start + b - a)
            pieces.append((plane, start, end))
            a += end - start
        runs.append(pieces)
    return runs


def texel_sums(env: np.ndarray, order: int) -> np.ndarray:
    """SH coefficients (order^2, C) of an angle map (N, N, C): the exact sums over its disk texels with
    their solid angles (to EPSILON), as sh.sh_coefficients defines them."""
    return real_from_alm(texel_sums_alm(env, order - 1), order)


def synthesise_at(alm: np.ndarray, lmax: int, loc: np.ndarray, epsilon: float = EPSILON) -> np.ndarray:
    """(K, C) values of the SH series alm (C, nalm) at locations loc (K, 2)."""
    return np.stack([_SHT.synthesis_general(alm=np.ascontiguousarray(a[None]), spin=0, lmax=lmax, loc=loc,
                                            epsilon=epsilon, nthreads=threads())[0] for a in alm], axis=1)


def synthesise_cc_grid(alm: np.ndarray, lmax: int, n_theta: int, n_phi: int, out: np.ndarray | None = None) -> np.ndarray:
    """(C, n_theta, n_phi) values on the grid theta_r = r pi/(n_theta-1), phi_c = 2 pi c/n_phi
    (ducc0's Clenshaw-Curtis geometry: the grid sh.sh_synthesis_grid has always used), written into out."""
    if out is None:
        out = np.empty((alm.shape[0], n_theta, n_phi), dtype=np.float32 if alm.dtype == np.complex64 else np.float64)
    for a, plane in zip(alm, out):
        _SHT.synthesis_2d(alm=np.ascontiguousarray(a[None]), spin=0, lmax=lmax, geometry="CC", ntheta=n_theta,
                          nphi=n_phi, nthreads=threads(), map=plane[None])
    return out


@functools.lru_cache(maxsize=256)
def bands_above(exponent: float, truncation: float) -> int:
    """Bands 0..b-1 that carry the Phong lobe's zonal coefficients down to `truncation`:
    kappa_l ~ exp(-l^2 / 2s) for large s, but only ~ l^-2.5 for s = 1 (the kink at the horizon: about
    300 bands at 1e-6)."""
    guess = int(np.ceil(np.sqrt(2.0 * exponent * np.log(1.0 / truncation)))) + 2
    kappa = phong_zonal_coefficients(exponent, max(guess, MAX_BANDS_SEARCH) + 1)
    above = np.flatnonzero(np.abs(kappa) >= truncation)
    return int(above[-1]) + 1


def bands_for_exponent(exponent: float, truncation: float = TRUNCATION) -> int:
    """bands_above, at least MIN_BANDS."""
    return max(MIN_BANDS, bands_above(exponent, truncation))


@functools.lru_cache(maxsize=64)
def _weight_map(n: int, exponent: float, bands: int) -> np.ndarray:
    """The lobe sum of the texel weights at every disk texel (the normaliser), through the same
    truncation and grid as the radiance, per (size, exponent): it depends on nothing else, so repeated
    bakes at one size pay for it once."""
    count = len(disk_locations(n))
    values = np.zeros((count, 1))
    _lobe_lookup(texel_sums_alm(np.ones((n, n, 1)), bands - 1, FAST_EPSILON), bands - 1, exponent, bands,
                 functools.partial(grid_coordinates, n), values, np.arange(count), np.ones(count))
    values = values[:, 0].copy()
    values.setflags(write=False)
    return values


def sht_prepare(env: np.ndarray, exponents: Sequence[float]) -> tuple[np.ndarray, int]:
    """The probe's alm (3, nalm) at the largest bandlimit the exponents need, and that lmax."""
    lmax = max(bands_for_exponent(s) for s in exponents) - 1
    return texel_sums_alm(np.asarray(env)[..., :3], lmax, FAST_EPSILON), lmax


@functools.lru_cache(maxsize=16)
def disk_solid_angles(n: int) -> np.ndarray:
    """The solid angles of the disk texels of an N x N angle map, row-major (kept per size)."""
    w = anglemap_solid_angles(n)[_disk_mask(n)]
    w.setflags(write=False)
    return w


@functools.lru_cache(maxsize=16)
def disk_index(n: int) -> np.ndarray:
    """The disk texels' indices in an N x N map, row-major (kept): writing a map's disk through them is
    about twice as fast as through the boolean mask."""
    index = np.flatnonzero(_disk_mask(n))
    index.setflags(write=False)
    return index


@functools.lru_cache(maxsize=16)
def _disk_mask(n: int) -> np.ndarray:
    mask = anglemap_disk_mask(n)
    mask.setflags(write=False)
    return mask


@functools.lru_cache(maxsize=32)
def grid_coordinates(n: int, n_theta: int, n_phi: int) -> tuple[np.ndarray, np.ndarray]:
    """Fractional (row, column) of every disk texel of an N x N angle map on the Clenshaw-Curtis grid
    (n_theta, n_phi) (kept: every bake at that size reuses them)."""
    loc = disk_locations(n)
    rows = loc[:, 0] / np.pi * (n_theta - 1)
    cols = loc[:, 1] / (2 * np.pi) * n_phi
    for a in (rows, cols):
        a.setflags(write=False)
    return rows, cols


@functools.lru_cache(maxsize=32)
def grid_directions(n_theta: int, n_phi: int) -> np.ndarray:
    """(n_theta * n_phi, 3) unit directions of the Clenshaw-Curtis grid's points, row-major (the inverse of
    sh_angles: d = (-sin theta cos phi, sin theta sin phi, cos theta)), kept per grid."""
    theta = np.arange(n_theta) * (np.pi / (n_theta - 1))
    phi = np.arange(n_phi) * (2 * np.pi / n_phi)
    sin_t = np.sin(theta)[:, None]
    d = np.empty((n_theta, n_phi, 3))
    d[..., 0] = -sin_t * np.cos(phi)
    d[..., 1] = sin_t * np.sin(phi)
    d[..., 2] = np.cos(theta)[:, None]
    d = d.reshape(-1, 3)
    d.setflags(write=False)
    return d


def grid_size(exponent: float, bands: int) -> tuple[int, int]:
    """(n_theta, n_phi) of the grid an exponent's map (its first `bands` bands) is synthesised on:
    GRID_SAMPLES_PER_BAND samples per band in theta of the bands above GRID_TRUNCATION, so that the bicubic
    lookup's error stays far below the truncation's, and at least one per band of all it carries: the
    irradiance lobe's long tail of small bands (303 bands, all but 48 below 1e-4). Measured on the bundled
    probes at 512² against brute force: the same worst mean error as with two samples a band for that tail,
    worst max 0.12/0.35/0.17 % against 0.11/0.35/0.17 % (README: `sht`), at half its grid's rows; with three
    samples a band above 1e-4 instead of four, 2.5 times the error."""
    n_theta = GRID_SAMPLES_PER_BAND * max(-(-bands // GRID_SAMPLES_PER_BAND), bands_for_exponent(exponent, GRID_TRUNCATION)) + 1
    return n_theta, 2 * (n_theta - 1)


def sht_map(env: np.ndarray, prepared: tuple[np.ndarray, int], exponent: float, out: np.ndarray | None = None) -> np.ndarray:
    """The map (N, N, 3) float32 of one exponent from sht_prepare's alm (into out, zeros outside the disk,
    where given)."""
    alm, lmax = prepared
    n = env.shape[0]
    bands = min(bands_for_exponent(exponent), lmax + 1)
    if out is None:
        out = np.zeros((n, n, 3), dtype=np.float32)
    _lobe_lookup(alm, lmax, exponent, bands, functools.partial(grid_coordinates, n), out.reshape(n * n, 3),
                 disk_index(n), _weight_map(n, float(exponent), bands))
    return out


def sht_maps(env: np.ndarray, exponents: Sequence[float]) -> np.ndarray:
    """Maps (E, N, N, 3) float32 for the exponents (written in place: no stacking copy)."""
    prepared = sht_prepare(env, exponents)
    n = env.shape[0]
    maps = np.zeros((len(exponents), n, n, 3), dtype=np.float32)
    for k, s in enumerate(exponents):
        sht_map(env, prepared, s, maps[k])
    return maps


# An equirect's rows are rings of equal latitude about +y: its texel sums are one ring-based adjoint
# transform (ducc0's Fejer grid, "F1": ring j at theta = (j + 1/2) pi / H, texel k at phi = (k + 1/2) 2 pi / W,
# each ring weighted by its texels' solid angle), far cheaper than the non-uniform one over its texels. The
# maps are convolutions with a rotationally symmetric lobe, so they are synthesised in that same frame (pole
# +y, phi the equirect's u: README, Conventions) and read at the angle map's texels there.


@functools.lru_cache(maxsize=4)
def _equirect_frame_texels(n: int) -> tuple[np.ndarray, np.ndarray]:
    """(theta / pi, phi / 2 pi) of every disk texel of an N x N angle map in the equirect's frame (its v, u)."""
    uv = direction_to_equirect_uv(anglemap_directions(n)[_disk_mask(n)])
    out = (np.ascontiguousarray(uv[:, 1]), np.ascontiguousarray(uv[:, 0]))
    for a in out:
        a.setflags(write=False)
    return out


def _equirect_frame_coordinates(n: int, n_theta: int, n_phi: int) -> tuple[np.ndarray, np.ndarray]:
    """Fractional (row, column) of every disk texel of an N x N angle map on the Clenshaw-Curtis grid
    (n_theta, n_phi) of the equirect's frame."""
    v, u = _equirect_frame_texels(n)
    return v * (n_theta - 1), u * n_phi


def _equirect_rings(h: int) -> np.ndarray:
    """The solid angle of a texel in each row of an H x 2H equirect (ducc0's ringfactor)."""
    return np.ascontiguousarray(equirect_solid_angles(h)[:, 0])


def _equirect_alm(planes: np.ndarray, lmax: int) -> np.ndarray:
    """alm (C, nalm) of sum_i L_i conj(Y_lm(w_i)) W_i over the texels of equirect planes (C, H, 2H), in the
    equirect's frame, in single precision (as FAST_EPSILON)."""
    h, w = planes.shape[1:]
    return np.stack([_SHT.adjoint_synthesis_2d(map=np.ascontiguousarray(p[None], dtype=np.float32), spin=0, lmax=lmax,
                                               geometry="F1", phi0=np.pi / w, ringfactor=_equirect_rings(h),
                                               nthreads=threads())[0] for p in planes])


def _lobe_lookup(alm: np.ndarray, lmax: int, exponent: float, bands: int, coordinates, out: np.ndarray,
                 index: np.ndarray, den: np.ndarray) -> None:
    """One exponent's lobe (its first `bands` bands) applied to alm (C, nalm) of lmax >= bands - 1, synthesised
    on its grid (grid_size) and read at the texels by coordinates(n_theta, n_phi), divided by den, into
    out[index] (cubic_lookup_into)."""
    # The alm of a smaller lmax are not a prefix in healpy's m-major layout: pick them out.
    l, m, _ = _alm_index(lmax)
    keep = (l < bands) & (m < bands)
    size = grid_size(exponent, bands)
    grid = rgba_grid(*size)  # (each channel synthesised straight into its lane)
    scaled = zonal_scale(alm[:, keep], phong_zonal_coefficients(exponent, bands)).astype(np.complex64, copy=False)
    synthesise_cc_grid(scaled, bands - 1, *size, out=np.moveaxis(grid, 2, 0)[:len(scaled)])
    cubic_lookup_into(out, index, grid.reshape(-1), *size, *coordinates(*size), den)


@functools.lru_cache(maxsize=64)
def _equirect_weight_map(h: int, n: int, exponent: float, bands: int) -> np.ndarray:
    """The lobe sum of an H x 2H equirect's texel weights at every disk texel of an N x N angle map (the
    normaliser, as _weight_map for an angle map), through the same truncation and grid as the radiance.
    The weights are equal along each ring, so their coefficients are zonal (m = 0) and so is the lobe sum:
    one column of the grid, synthesised and read in theta alone. Kept per (H, N, exponent)."""
    alm = _SHT.adjoint_synthesis_2d(map=np.ones((1, h, 2 * h)), spin=0, lmax=bands - 1, mmax=0, geometry="F1",
                                    phi0=np.pi / (2 * h), ringfactor=_equirect_rings(h), nthreads=threads())
    n_theta, _ = grid_size(exponent, bands)
    # (Four equal columns, read at the second: a lookup whose columns need no wrapping, the maps' own
    # compiled variant.)
    columns = _SHT.synthesis_2d(alm=alm * phong_zonal_coefficients(exponent, bands), spin=0, lmax=bands - 1, mmax=0,
                                geometry="CC", ntheta=n_theta, nphi=4, nthreads=threads())
    rows, _ = _equirect_frame_coordinates(n, n_theta, 4)
    values = np.zeros((rows.size, 1), dtype=np.float32)
    grid = rgba_grid(n_theta, 4)
    grid[..., 0] = columns[0]
    cubic_lookup_into(values, np.arange(rows.size), grid.reshape(-1), n_theta, 4, rows, np.ones(rows.size),
                      np.ones(rows.size))
    values = values[:, 0].astype(np.float64)
    values.setflags(write=False)
    return values


def equirect_texel_sums(source: np.ndarray, order: int) -> np.ndarray:
    """SH coefficients (order^2, 3) of an equirect (H, 2H, C) summed over its own texels with their solid
    angles (to EPSILON), in the SH frame, as texel_sums has them for an angle map: what `sh` sums an equirect
    larger than its map by (methods.sums_source)."""
    h = source.shape[0]
    theta, phi = sh_angles(equirect_directions(h).reshape(-1, 3))
    loc = np.stack([theta, phi], axis=1)
    weighted = (np.asarray(source, dtype=np.float64).reshape(-1, source.shape[2])[:, :3]
                * equirect_solid_angles(h).reshape(-1, 1)).T
    return real_from_alm(adjoint_at(weighted, loc, order - 1, EPSILON), order)


def sht_maps_from_source(source: np.ndarray, n: int, exponents: Sequence[float]) -> np.ndarray:
    """Maps (E, n, n, 3) float32 from a source at its own resolution and layout (angle map or equirect):
    the texel sums run over the source's texels, so nothing is resampled before the lobe averages (a
    small bright source keeps its energy); the normaliser is the source's own lobe sum of weights."""
    lmax = max(bands_for_exponent(s) for s in exponents) - 1
    maps = np.zeros((len(exponents), n * n, 3), dtype=np.float32)
    if detect_layout(source, "source") == "equirect":
        h = source.shape[0]
        alm = _equirect_alm(np.moveaxis(np.asarray(source)[..., :3], 2, 0), lmax)
        coordinates = functools.partial(_equirect_frame_coordinates, n)
        for k, s in enumerate(exponents):
            bands = bands_for_exponent(s)
            _lobe_lookup(alm, lmax, s, bands, coordinates, maps[k], disk_index(n), _equirect_weight_map(h, n, float(s), bands))
        return maps.reshape(len(exponents), n, n, 3)
    # an angle map: its radiance and its texel weights (a channel of ones), summed over its disk texels
    alm = texel_sums_alm(np.concatenate([np.asarray(source)[..., :3], np.ones(source.shape[:2] + (1,))], axis=-1),
                         lmax, FAST_EPSILON)
    count = len(disk_locations(n))
    coordinates = functools.partial(grid_coordinates, n)
    for k, s in enumerate(exponents):
        bands = bands_for_exponent(s)
        den = np.zeros((count, 1))
        _lobe_lookup(alm[3:], lmax, s, bands, coordinates, den, np.arange(count), np.ones(count))
        _lobe_lookup(alm[:3], lmax, s, bands, coordinates, maps[k], disk_index(n), den[:, 0])
    return maps.reshape(len(exponents), n, n, 3)
