"""Spherical-harmonic maps (thesis Alg. 4.4-4.7), stable to high order, and the thesis's own evaluation.

Frame: as in Alg. 4.4/4.7, the SH pole is the angle map's centre (+z), theta = pi rho, and the azimuth is
phi = atan2(d_y, -d_x) (the thesis's u = 1 - 2s, v = 2t - 1). Real SH with the Condon-Shortley phase
(eq. 2.27); coefficients are stored as the thesis does, index l(l+1)+m, order o = bands 0..o-1.

Coefficients: c_lm = sum_i L_i Y_lm(w_i) W_i over the disk texels with their solid angles W_i
(Alg. 4.4/4.5), computed by ducc0's adjoint non-uniform SH transform (sht.texel_sums, 1e-12 relative)
above RINGS_MAX_ORDER, and up to it by the ring sums (compiled: sh_kernel.orbit_partials and project_rings,
without ducc0's fixed cost per call), whose NumPy version is the reference: texels at the same disk radius
share theta, so the Legendre functions are evaluated once per distinct radius (about N^2/17 of them) and the
azimuthal sums per ring, from each symmetry orbit's partial sums (_Orbits).

Maps: M_s = sum_l kappa_l(s) w_l sum_m c_lm Y_lm (eq. 2.31, 2.33; w_l a window, 1 for plain truncation)
is evaluated exactly at the texels up to DIRECT_MAX_ORDER and beyond GRID_MAX_ORDER (ducc0's
non-uniform synthesis; up to RINGS_MAX_ORDER per ring of equal polar angle and per symmetry orbit instead),
and between them synthesised by ducc0 on a fine (theta, phi) grid and sampled bilinearly at the texel
directions, as it always was -- except, above GRID_SPARED_FROM, lobes that carry few bands (evaluated at the
texels). Every synthesis stops at the last band whose zonal factor is above
BAND_NEGLIGIBLE (carrying_bands): what the narrow lobes leave out at high orders.

Y_lm evaluation: `stable` uses orthonormalised recurrences (no factorials), exact to any order used
here. `faithful` evaluates Alg. 2.5/2.6 as printed: unnormalised P_l^m by Green's recurrence and
K_l^m from factorials in double precision; (l+|m|)! overflows beyond 170, so K becomes 0 and
P_l^m infinite, whose product is NaN, which Alg. 4.7 (lines 25-33) zeroes.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.fft

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask
from arsim.core.errors import ArsimError
from arsim.lighting.phong import phong_zonal_coefficients
from arsim.lighting.sh_kernel import bilinear_lookup, lookup_channels_into, orbit_partials, orbit_series, project_rings
from arsim.lighting.sht import (alm_bands, alm_from_real, disk_index, disk_locations, disk_solid_angles, sh_angles,
                                synthesise_at, synthesise_cc_grid, texel_sums)

MAX_ORDER = 1024
# Up to this order the maps are evaluated directly at every texel (exact); up to GRID_MAX_ORDER through a
# (theta, phi) grid and bilinear lookups (as they always were); beyond, directly again (a grid of 4 samples
# per band would not fit in memory).
DIRECT_MAX_ORDER = 16
GRID_MAX_ORDER = 512
# Up to this order the direct evaluation runs per ring of equal polar angle and per orbit of the square grid's
# symmetry (_evaluate_disk_rings) rather than through ducc0, whose fixed cost per call dominates there (at 512²,
# nine maps: 0.014-0.017 s at order 10 and 0.022-0.024 s at order 16, where ducc0 takes about 0.015 s a map and
# channel).
# Beyond it the Legendre sums per ring grow as the order squared: 0.07 s at order 32 against the grid's 0.035 s.
RINGS_MAX_ORDER = DIRECT_MAX_ORDER
# Above this order, a map whose lobe carries at most DIRECT_BANDS bands (carrying_bands) is evaluated at
# the texels rather than on the order's grid: at 512², one such synthesis takes 0.05-0.1 s, the grid of
# order 512 0.25 s per map (and the grid's bilinear error goes with it).
GRID_SPARED_FROM = 128
DIRECT_BANDS = 320

# sh's windows against ringing (README: Irradiance and reflection maps), factors w_l for l < order.
WINDOWS = ("none", "hann", "lanczos", "sloan")
SLOAN_FLOOR = 0.01  # sloan: the window falls to this at l = order


def sh_window(name: str, order: int) -> np.ndarray:
    """Factors w_l, l = 0..order-1, that multiply the zonal coefficients: `none` plain truncation; `hann`
    (1 + cos(pi l / order)) / 2; `lanczos` sinc(l / order); `sloan` 1 / (1 + lambda l^2 (l+1)^2), the
    Laplacian-penalty deringing of Sloan (minimising the squared error plus lambda times the squared
    Laplacian), lambda set so that the factor is SLOAN_FLOOR at l = order."""
    l = np.arange(order, dtype=np.float64)
    if name == "none":
        return np.ones(order)
    if name == "hann":
        return 0.5 * (1.0 + np.cos(np.pi * l / order))
    if name == "lanczos":
        return np.sinc(l / order)
    if name == "sloan":
        lam = (1.0 / SLOAN_FLOOR - 1.0) / (order * order * (order + 1.0) ** 2)
        return 1.0 / (1.0 + lam * (l * (l + 1.0)) ** 2)
    raise ArsimError(f"SH window '{name}' is unknown; use one of {', '.join(WINDOWS)}")


# ----------------------------------------------------------------------------------------------------
# Associated Legendre functions, one m at a time for l = m .. order-1, vectorised over cos(theta)


def _legendre_stable(m: int, order: int, x: np.ndarray, p_mm: np.ndarray) -> np.ndarray:
    """Orthonormalised P~_lm (Y_l0 = P~_l0) for l = m..order-1 given P~_mm; shape (order-m, len(x)).

    P~_lm = a (x P~_(l-1)m) - a b P~_(l-2)m, written with in-place products: this loop is most of the
    time of a high-order SH bake."""
    out = np.empty((order - m, x.size))
    out[0] = p_mm
    if order - m > 1:
        np.multiply(x, p_mm, out=out[1])
        out[1] *= math.sqrt(2 * m + 3)
    scratch = np.empty(x.size)
    for l in range(m + 2, order):
        a = math.sqrt((4 * l * l - 1) / (l * l - m * m))
        ab = a * math.sqrt(((l - 1) ** 2 - m * m) / (4 * (l - 1) ** 2 - 1))
        current = out[l - m]
        np.multiply(x, out[l - m - 1], out=current)
        current *= a
        np.multiply(out[l - m - 2], ab, out=scratch)
        current -= scratch
    return out


def _next_p_mm(m: int, p_prev: np.ndarray, sin_theta: np.ndarray) -> np.ndarray:
    """P~_mm from P~_(m-1)(m-1), Condon-Shortley phase included."""
    return -np.sqrt((2 * m + 1) / (2 * m)) * sin_theta * p_prev


def _factorial(n: int) -> float:
    """n! in double precision as Alg. 2.6 computes it: a running product, inf beyond 170."""
    result = np.float64(1.0)
    with np.errstate(over="ignore"):
        for k in range(2, n + 1):
            result = result * np.float64(k)
    return float(result)


def _legendre_faithful(m: int, order: int, x: np.ndarray) -> np.ndarray:
    """K_l^m P_l^m (Alg. 2.5/2.6 as printed) for l = m..order-1; same scale as _legendre_stable."""
    with np.errstate(over="ignore", invalid="ignore"):
        somx2 = np.sqrt((1.0 - x) * (1.0 + x))  # Alg. 2.5's typo: sqrt(1 - x^2) is meant
        pmm = np.ones_like(x)
        fact = 1.0
        for _ in range(m):
            pmm = pmm * (-fact) * somx2
            fact += 2.0
        p = np.empty((order - m, x.size))
        p[0] = pmm
        if order - m > 1:
            p[1] = x * (2 * m + 1) * pmm
        for l in range(m + 2, order):
            p[l - m] = ((2 * l - 1) * x * p[l - m - 1] - (l + m - 1) * p[l - m - 2]) / (l - m)
        k = np.array([np.sqrt((2 * l + 1) * _factorial(l - m) / (4 * np.pi * _factorial(l + m))) for l in range(m, order)])
        return k[:, None] * p


class _Legendre:
    """Iterates m = 0..order-1, giving the (order-m, len(x)) block of K P_lm for each."""

    def __init__(self, theta: np.ndarray, order: int, faithful: bool):
        self.x, self.sin, self.order, self.faithful = np.cos(theta), np.sin(theta), order, faithful

    def __iter__(self):
        p_mm = np.full(self.x.size, 1.0 / np.sqrt(4 * np.pi))
        for m in range(self.order):
            if m > 0:
                p_mm = _next_p_mm(m, p_mm, self.sin)
            if self.faithful:
                yield m, _legendre_faithful(m, self.order, self.x)
            else:
                yield m, _legendre_stable(m, self.order, self.x, p_mm)


# ----------------------------------------------------------------------------------------------------
# Coefficients (Alg. 4.4/4.5)


@dataclass(frozen=True)
class _Orbits:
    """Disk texels grouped by the symmetry of the square grid, and the orbits by exact disk radius.

    A texel at half-texel offsets (X, Y) from the centre has azimuth phi = sigma alpha + k pi/2, with
    alpha the angle of its orbit (|X|, |Y| sorted) and sigma = +-1, k = 0..3. So e^{i m phi} =
    e^{i m sigma alpha} i^{m k}, and the azimuthal sums of a whole orbit for every m need only its
    sums per (sigma, k mod 4): the per-m work is over orbits (about N^2/8), not texels."""

    theta: np.ndarray  # (R,) polar angle of each ring
    ring_starts: np.ndarray  # start of each ring in the (ring-sorted) orbit order
    alpha: np.ndarray  # (O,) orbit angles, orbits sorted by ring
    texel_orbit: np.ndarray  # (M,) orbit of each disk texel (disk texels in row-major order)
    texel_sigma: np.ndarray  # (M,) +1 or -1
    texel_k: np.ndarray  # (M,) 0..3

    @classmethod
    def of(cls, n: int) -> _Orbits:
        inside = anglemap_disk_mask(n)
        c = 2 * np.arange(n) + 1 - n  # texel centres in half-texel units: exact integers
        x = np.broadcast_to(c[None, :], (n, n))[inside]  # along +x (image right)
        y = np.broadcast_to(-c[:, None], (n, n))[inside]  # along +y (image up)
        lo, hi = np.minimum(np.abs(x), np.abs(y)), np.maximum(np.abs(x), np.abs(y))
        ring_key = lo.astype(np.int64) ** 2 + hi.astype(np.int64) ** 2
        orbit_key = ring_key * (2 * n + 1) + lo  # unique per (lo, hi); sorts by ring first
        keys, texel_orbit = np.unique(orbit_key, return_inverse=True)
        orbit_lo, orbit_ring = keys % (2 * n + 1), keys // (2 * n + 1)
        alpha = np.arctan2(np.sqrt((orbit_ring - orbit_lo**2).astype(np.float64)), -orbit_lo.astype(np.float64))
        ring_starts = np.flatnonzero(np.r_[True, orbit_ring[1:] != orbit_ring[:-1]])
        theta = np.pi * np.sqrt(orbit_ring[ring_starts].astype(np.float64)) / n
        # Each texel's phi as sigma * alpha + k pi/2 (alpha here measured in the same atan2(y, -x) frame).
        phi = np.arctan2(y.astype(np.float64), -x.astype(np.float64))
        base = alpha[texel_orbit]
        k_plus = np.round((phi - base) / (np.pi / 2))
        ok_plus = np.abs(phi - base - k_plus * np.pi / 2) < 1e-9
        k_minus = np.round((phi + base) / (np.pi / 2))
        sigma = np.where(ok_plus, 1, -1)
        k = np.mod(np.where(ok_plus, k_plus, k_minus), 4).astype(np.int64)
        return cls(theta, ring_starts, alpha, texel_orbit, sigma, k)


@functools.lru_cache(maxsize=4)
def _orbits(n: int) -> _Orbits:
    return _Orbits.of(n)


def sh_coefficients(env: np.ndarray, order: int, faithful: bool = False, compiled: bool = True) -> np.ndarray:
    """SH coefficients (order^2, C) of an angle map (N, N, C), summed over its disk texels with their
    solid angles: through ducc0's adjoint non-uniform SH transform (sht.texel_sums, to 1e-12 relative), and up to
    RINGS_MAX_ORDER per ring and symmetry orbit, compiled (the same sums to rounding, without ducc0's fixed cost
    per call: at 512², 7-12 ms against 20 ms). compiled=False runs the ring sums in NumPy (the reference);
    faithful, the thesis's factorials."""
    if compiled and not faithful and order > RINGS_MAX_ORDER:
        return texel_sums(env, order)
    return _sh_coefficients_rings(env, order, faithful, compiled)


def _sh_coefficients_rings(env: np.ndarray, order: int, faithful: bool = False, compiled: bool = True) -> np.ndarray:
    """The texel sums per ring of equal disk radius and per symmetry orbit: compiled (sh_kernel.orbit_partials
    and project_rings), or NumPy (the reference, and the faithful route)."""
    n = env.shape[0]
    orbits = _orbits(n)
    n_orbits = orbits.alpha.size
    inside = anglemap_disk_mask(n)
    lw = env[inside].astype(np.float64) * disk_solid_angles(n)[:, None]
    if not faithful and compiled:
        _, _, _, orbit_texels, rows, _, sigma, quarter = _orbit_layout(n)
        partial = orbit_partials(lw, orbit_texels, rows, sigma, quarter)
    else:
        # Per orbit, per sigma and per r = m mod 4: sum of L W i^(r k).
        partial = np.zeros((2, 4, n_orbits, lw.shape[1]), dtype=np.complex128)
        for r in range(4):
            phase = (1j) ** ((r * orbits.texel_k) % 4)  # i^(m k) depends on m only through m mod 4
            for side, sign in enumerate((1, -1)):
                sel = orbits.texel_sigma == sign
                for ch in range(lw.shape[1]):
                    weights = lw[sel, ch] * phase[sel]
                    partial[side, r, :, ch] = (np.bincount(orbits.texel_orbit[sel], weights.real, n_orbits)
                                               + 1j * np.bincount(orbits.texel_orbit[sel], weights.imag, n_orbits))
    channels = lw.shape[1]
    if not faithful and compiled:
        ring_of_orbit = np.repeat(np.arange(orbits.ring_starts.size), np.diff(np.r_[orbits.ring_starts, n_orbits]))
        projected = project_rings(np.cos(orbits.theta), np.sin(orbits.theta), ring_of_orbit, orbits.alpha,
                                  partial, order)
        coeffs = np.zeros((order * order, channels))
        for m in range(order):
            ls = np.arange(m, order)
            _store_rows(coeffs, m, ls, projected[m, m:])
        return coeffs
    coeffs = np.zeros((order * order, channels))
    step = np.exp(1j * orbits.alpha)
    z = np.ones_like(step)
    for m, p in _Legendre(orbits.theta, order, faithful):
        if m > 0:
            z = z * step
        per_orbit = z[:, None] * partial[0, m % 4]
        per_orbit += np.conj(z)[:, None] * partial[1, m % 4]
        ring_sums = np.add.reduceat(per_orbit, orbits.ring_starts, axis=0)  # (R, C): sum L W e^{i m phi}
        with np.errstate(invalid="ignore", over="ignore"):
            _store_rows(coeffs, m, np.arange(m, order), p @ ring_sums.view(np.float64))  # real BLAS on (re, im)
    return np.nan_to_num(coeffs, nan=0.0, posinf=0.0, neginf=0.0) if faithful else coeffs


def _store_rows(coeffs: np.ndarray, m: int, ls: np.ndarray, projected: np.ndarray) -> None:
    """Rows l(l+1) +- m of the real coefficients from the complex projections (l = ls, (re, im) per channel)."""
    if m == 0:
        coeffs[ls * (ls + 1)] = projected[:, 0::2]
    else:
        coeffs[ls * (ls + 1) + m] = np.sqrt(2.0) * projected[:, 0::2]
        coeffs[ls * (ls + 1) - m] = np.sqrt(2.0) * projected[:, 1::2]


# ----------------------------------------------------------------------------------------------------
# Maps (Alg. 4.6/4.7)


def sh_synthesis_grid(coeffs: np.ndarray, kappas: np.ndarray, n_theta: int, n_phi: int,
                      faithful: bool = False, compiled: bool = True) -> np.ndarray:
    """Values (E, C, n_theta, n_phi) of sum_lm kappa_l c_lm Y_lm on the grid theta_r = r pi/(n_theta-1),
    phi_c = 2 pi c / n_phi, for E sets of zonal factors kappas (E, order). compiled=False: NumPy (reference)."""
    n_maps, order = kappas.shape
    channels = coeffs.shape[1]
    if compiled and not faithful:  # ducc0's synthesis on its Clenshaw-Curtis grid: the same grid
        out = np.empty((n_maps, channels, n_theta, n_phi))
        for k, planes in zip(kappas, out):
            bands = carrying_bands(k)  # the same grid, only the bands the lobe carries synthesised
            synthesise_cc_grid(alm_from_real(coeffs[: bands * bands], bands) * k[alm_bands(bands - 1)], bands - 1,
                               n_theta, n_phi, out=planes)
        return out
    theta = np.linspace(0.0, np.pi, n_theta)
    # Per m, the weighted coefficients as the spectrum of phi:
    # sum_m sqrt2 (a_m cos m phi + b_m sin m phi) = Re sum_m sqrt2 (a_m - i b_m) e^{i m phi}
    weighted = np.zeros((order, order, n_maps * channels), dtype=np.complex128)  # [m, l, (map, channel)]
    for m in range(order):
        ls = np.arange(m, order)
        a = coeffs[ls * (ls + 1) + m]  # (order-m, C)
        a = (n_phi / 2) * np.sqrt(2.0) * (a - 1j * coeffs[ls * (ls + 1) - m]) if m > 0 else n_phi * a
        weighted[m, m:] = (kappas[:, m:, None] * a[None]).transpose(1, 0, 2).reshape(order - m, -1)
    # The NumPy reference and the faithful route:
    spectrum = np.zeros((n_maps * channels, n_theta, n_phi // 2 + 1), dtype=np.complex128)
    for m, p in _Legendre(theta, order, faithful):
        with np.errstate(invalid="ignore", over="ignore"):
            if faithful:
                p = np.nan_to_num(p, nan=0.0, posinf=0.0, neginf=0.0)
            spectrum[:, :, m] = weighted[m, m:].T @ p  # (E*C, n_theta), BLAS
    return scipy.fft.irfft(spectrum, n=n_phi, axis=-1, workers=-1).reshape(n_maps, channels, n_theta, n_phi)


@dataclass(frozen=True)
class _GridSampler:
    """Bilinear lookups of (theta, phi) grids at fixed directions, indices and weights computed once."""

    index: np.ndarray  # (K, 4) flat grid indices of the four corners
    weight: np.ndarray  # (K, 4)

    @classmethod
    def of(cls, directions: np.ndarray, n_theta: int, n_phi: int) -> _GridSampler:
        theta, phi = sh_angles(directions)
        r = np.clip(theta / np.pi * (n_theta - 1), 0, n_theta - 1)
        c = phi / (2 * np.pi) * n_phi
        r0 = np.minimum(r.astype(np.int64), n_theta - 2)
        c0 = np.floor(c).astype(np.int64)
        fr, fc = r - r0, c - c0
        c0 %= n_phi
        c1 = (c0 + 1) % n_phi  # longitude wraps
        index = np.stack([r0 * n_phi + c0, r0 * n_phi + c1, (r0 + 1) * n_phi + c0, (r0 + 1) * n_phi + c1], axis=1)
        weight = np.stack([(1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc], axis=1)
        return cls(index, weight)

    def __call__(self, grid: np.ndarray) -> np.ndarray:
        """(K, C) samples of a (C, n_theta, n_phi) grid."""
        texels = np.ascontiguousarray(grid.reshape(grid.shape[0], -1).T)  # one row fetches all channels
        return bilinear_lookup(texels, self.index, self.weight)


@functools.lru_cache(maxsize=8)
def _disk_sampler(n: int, n_theta: int, n_phi: int) -> _GridSampler:
    """The sampler of every disk texel of an N x N angle map (kept: bakes map by map reuse it)."""
    return _GridSampler.of(anglemap_directions(n)[anglemap_disk_mask(n)], n_theta, n_phi)


def synthesis_grid_size(order: int) -> tuple[int, int]:
    """(n_theta, n_phi) of the synthesis grid: four samples per band in theta, so that bilinear
    sampling adds at most a few 0.1 % to the maps (measured against direct evaluation)."""
    n_theta = 4 * order + 1
    return n_theta, 2 * (n_theta - 1)


def sh_evaluate(coeffs: np.ndarray, kappas: np.ndarray, directions: np.ndarray, faithful: bool = False) -> np.ndarray:
    """sum_lm kappa_l c_lm Y_lm evaluated directly at directions (K, 3): (E, K, C). Costs order² K; the
    maps use it up to DIRECT_MAX_ORDER and the synthesis grid beyond."""
    n_maps, order = kappas.shape
    theta, phi = sh_angles(directions)
    out = np.zeros((n_maps, theta.size, coeffs.shape[1]))
    for m, p in _Legendre(theta, order, faithful):
        ls = np.arange(m, order)
        if faithful:
            p = np.nan_to_num(p, nan=0.0, posinf=0.0, neginf=0.0)
        for e in range(n_maps):
            radial = p.T @ (kappas[e, m:, None] * coeffs[ls * (ls + 1) + m])  # (K, C)
            if m == 0:
                out[e] += radial
            else:
                radial_sin = p.T @ (kappas[e, m:, None] * coeffs[ls * (ls + 1) - m])
                out[e] += np.sqrt(2.0) * (radial * np.cos(m * phi)[:, None] + radial_sin * np.sin(m * phi)[:, None])
    return out


def probe_with_weights(env: np.ndarray) -> np.ndarray:
    """The angle map with a fourth channel of ones: its SH coefficients carry the texel weights' own
    (normalising) sum beside the radiance, as Alg. 4.1 divides by sum f W."""
    return np.concatenate([np.asarray(env, dtype=np.float64)[..., :3], np.ones(env.shape[:2] + (1,))], axis=-1)


# Bands whose zonal factor is below this (relative to band 0's) are left out of a map's synthesis. A band's
# term is at most kappa_l (2l + 1) times band 0's (a single bright texel: every band alike), so at order 1024
# what is left out stays below 3e-9 of the map: under float32's resolution, and under the transforms' 1e-12
# relative accuracy at the bands that matter. It spares high orders the bands narrow lobes do not carry
# (kappa_l ~ exp(-l^2 / 2s): about 270 bands at s = 1280, 24 at s = 10), which made order 1024 cost 20
# times order 64.
BAND_NEGLIGIBLE = 1e-12


def carrying_bands(kappa: np.ndarray) -> int:
    """1 + the last band whose zonal factor kappa (order,) is at least BAND_NEGLIGIBLE of kappa_0's."""
    above = np.flatnonzero(np.abs(kappa) >= BAND_NEGLIGIBLE * abs(kappa[0]))
    return int(above[-1]) + 1 if above.size else 1


@functools.lru_cache(maxsize=4)
def _orbit_layout(n: int) -> tuple[np.ndarray, ...]:
    """The disk texels as sh_kernel.orbit_series walks them (_Orbits): each ring's first orbit (rings + 1), the
    cosine and sine of the orbits' angles, each orbit's first texel (orbits + 1), and per texel, grouped by orbit,
    its row among the disk texels and its index in the N x N map (both row-major), sigma and quarter turns k."""
    orbits = _orbits(n)
    by_orbit = np.argsort(orbits.texel_orbit, kind="stable")
    orbit_texels = np.searchsorted(orbits.texel_orbit[by_orbit], np.arange(orbits.alpha.size + 1))
    out = (np.r_[orbits.ring_starts, orbits.alpha.size], np.cos(orbits.alpha), np.sin(orbits.alpha), orbit_texels,
           by_orbit, np.flatnonzero(anglemap_disk_mask(n))[by_orbit], orbits.texel_sigma[by_orbit].astype(np.float64),
           orbits.texel_k[by_orbit])
    for a in out:
        a.setflags(write=False)
    return out


@functools.lru_cache(maxsize=2)
def _ring_legendre(n: int, order: int) -> np.ndarray:
    """The orthonormal P_lm at the polar angles of the disk's rings (_Orbits: about N²/17 at 512²), (rings,
    order (order + 1) / 2) packed m by m as _lm_packing gives (kept: bakes map by map reuse it; 16 MB at order
    16, 512²)."""
    out = np.ascontiguousarray(np.concatenate([p.T for _, p in _Legendre(_orbits(n).theta, order, False)], axis=1))
    out.setflags(write=False)
    return out


def _lm_packing(order: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For the packing of _ring_legendre: where each m starts (order + 1,), and per entry its l and m."""
    m = np.concatenate([np.full(order - k, k) for k in range(order)])
    l = np.concatenate([np.arange(k, order) for k in range(order)])
    return np.concatenate([[0], np.cumsum(np.arange(order, 0, -1))]), l, m


def _evaluate_disk_rings(coeffs: np.ndarray, kappas: np.ndarray, n: int, maps: np.ndarray, which: list[int],
                         normalise: bool) -> None:
    """_evaluate_disk for low orders, exactly (up to rounding) and without ducc0's per-call cost (about
    0.015 s a channel at 512², more than order 64's whole grid), written into maps[which] (normalised as sh_maps
    does): the Legendre sums per ring of equal polar angle, the azimuthal series once per orbit of the square
    grid's symmetry and combined for each of its up to eight texels, in one compiled pass for all the maps
    (sh_kernel.orbit_series)."""
    n_maps, order = kappas.shape
    ring_orbits, cos_alpha, sin_alpha, orbit_texels, _, texel, sigma, quarter = _orbit_layout(n)
    channels = coeffs.shape[1]
    first, l, m = _lm_packing(order)
    scale = np.where(m > 0, np.sqrt(2.0), 1.0)
    # weights[j, packed lm, (map, channel)]: the cos (j = 0) and sin (1) terms' factors, a column per map and channel
    weighted = (scale * kappas[:, l])[:, :, None]  # (E, packed lm, 1)
    weights = np.stack([weighted * coeffs[l * (l + 1) + m][None],
                        np.where(m[None, :, None] > 0, weighted * coeffs[l * (l + 1) - m][None], 0.0)])
    weights = np.ascontiguousarray(weights.transpose(0, 2, 1, 3).reshape(2, l.size, n_maps * channels))
    orbit_series(_ring_legendre(n, order), first, weights, ring_orbits, cos_alpha, sin_alpha, orbit_texels, texel,
                 sigma, quarter, maps.reshape(maps.shape[0], n * n, 3), np.asarray(which, dtype=np.int64), channels,
                 normalise)


def _evaluate_disk(coeffs: np.ndarray, kappas: np.ndarray, n: int) -> np.ndarray:
    """sum_lm kappa_l c_lm Y_lm at every disk texel, (E, K, C), by ducc0's non-uniform synthesis (exact
    to 1e-12 relative, as sh_evaluate is exactly), each map over the bands its lobe carries."""
    out = []
    for k in kappas:
        bands = carrying_bands(k)
        alm = alm_from_real(coeffs[: bands * bands], bands)
        out.append(synthesise_at(alm * k[alm_bands(bands - 1)], bands - 1, disk_locations(n)))
    return np.stack(out)


def sh_maps(env: np.ndarray, exponents: Sequence[float], order: int | Sequence[int], faithful: bool = False,
            coeffs: np.ndarray | None = None, normalise: bool = False, window: str = "none") -> np.ndarray:
    """Maps (E, N, N, 3) float32 from SH (bands 0..order-1); 0 outside the disk.

    order may be one per exponent (`fast` gives each the order its lobe needs); the coefficients are
    computed once, at the largest order. normalise divides by the SH image of the weights (coeffs of
    probe_with_weights), like Alg. 4.1's sum f W; Alg. 4.7 does not, and is reproduced without. window
    (WINDOWS) multiplies the zonal coefficients by sh_window's factors (`none`: plain truncation)."""
    n = env.shape[0]
    orders = [int(order)] * len(exponents) if np.isscalar(order) else [int(o) for o in order]
    if coeffs is None:
        source = probe_with_weights(env) if normalise else env
        coeffs = sh_coefficients(source, max(orders), faithful)
    inside = anglemap_disk_mask(n)
    maps = np.zeros((len(exponents), n, n, 3), dtype=np.float32)
    groups = []
    for o in sorted(set(orders)):
        which = [k for k, ok in enumerate(orders) if ok == o]
        kappas = np.stack([phong_zonal_coefficients(exponents[k], o) for k in which]) * sh_window(window, o)
        if not faithful and DIRECT_MAX_ORDER < o <= GRID_MAX_ORDER and o > GRID_SPARED_FROM:
            # A narrow lobe's few bands, evaluated at the texels (exact), cost less than the order's grid.
            spared = np.array([carrying_bands(k) <= DIRECT_BANDS for k in kappas])
            groups.append((o, [k for k, d in zip(which, spared) if d], kappas[spared], True))
            which, kappas = [k for k, d in zip(which, spared) if not d], kappas[~spared]
        groups.append((o, which, kappas, False))
    for o, which, kappas, direct in groups:
        if not which:
            continue
        if direct:
            all_values = _evaluate_disk(coeffs, kappas, n)
        elif faithful and o <= DIRECT_MAX_ORDER:
            all_values = sh_evaluate(coeffs[: o * o], kappas, anglemap_directions(n)[inside], faithful)
        elif not faithful and o <= RINGS_MAX_ORDER:
            _evaluate_disk_rings(coeffs, kappas, n, maps, which, normalise)  # (into the maps: no scatter after)
            continue
        elif not faithful and (o <= DIRECT_MAX_ORDER or o > GRID_MAX_ORDER):
            all_values = _evaluate_disk(coeffs, kappas, n)
        else:
            size = synthesis_grid_size(o)
            sampler = _disk_sampler(n, *size)
            for grid, k in zip(sh_synthesis_grid(coeffs[: o * o], kappas, *size, faithful=faithful), which):
                lookup_channels_into(maps.reshape(len(exponents), n * n, 3), k, disk_index(n),
                                     grid.reshape(grid.shape[0], -1), sampler.index, sampler.weight, normalise)
            continue
        flat = maps.reshape(len(exponents), n * n, 3)
        for values, k in zip(all_values, which):
            if normalise:
                den = values[:, 3:]
                values = np.divide(values[:, :3], den, out=np.zeros_like(values[:, :3]), where=den > 0)
            flat[k, disk_index(n)] = values
    return maps
