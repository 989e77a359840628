"""Compiled loops of the SH maps: the ring sums times associated Legendre functions for every (l, m) that
computed `sh_coefficients` before ducc0 (kept as a reference), and the grid lookups of sh.py and sht.py.

Per m, the azimuthal sums of each ring are gathered from its orbits' partial sums, then the orthonormal
Legendre recurrence runs over the rings in blocks small enough for the first-level cache, with the
projections accumulated as it goes, so that the (order^2/2 x rings) Legendre table is never stored.
Threads take whole m values (numba prange), large and small m interleaved so the shares are equal.
The NumPy path in sh.py computes the same sums (up to rounding) and is the reference in the tests.
"""

from __future__ import annotations

import math

import numba
import numpy as np

RING_BLOCK = 128


@numba.njit(cache=True)
def _interleaved(order):  # pragma: no cover (compiled)
    """0, order-1, 1, order-2, ...: the m values in an order that gives each half of a static split of
    the prange equal work (the work of m falls with m)."""
    perm = np.empty(order, dtype=np.int64)
    lo, hi = 0, order - 1
    for k in range(order):
        if k % 2 == 0:
            perm[k] = lo
            lo += 1
        else:
            perm[k] = hi
            hi -= 1
    return perm


@numba.njit(cache=True)
def _recurrence(m, order):  # pragma: no cover (compiled)
    """For l = m..order-1 (index l - m): the factors a, ab of P~_lm = a x P~_(l-1)m - ab P~_(l-2)m; and the
    constants of P~_mm = pmm_factor (-sin theta)^m and P~_(m+1)m = start1 x P~_mm."""
    n_l = order - m
    ca = np.zeros(n_l)
    cab = np.zeros(n_l)
    for j in range(2, n_l):
        l = m + j
        ca[j] = math.sqrt((4.0 * l * l - 1.0) / (l * l - m * m))
        cab[j] = ca[j] * math.sqrt(((l - 1.0) ** 2 - m * m) / (4.0 * (l - 1.0) ** 2 - 1.0))
    pmm_factor = 1.0 / math.sqrt(4.0 * math.pi)  # Condon-Shortley phase in the (-sin theta)^m
    for q in range(1, m + 1):
        pmm_factor *= math.sqrt((2.0 * q + 1.0) / (2.0 * q))
    return ca, cab, pmm_factor, math.sqrt(2.0 * m + 3.0)


@numba.njit(parallel=True, cache=True, fastmath=True)
def project_rings(cos_theta, sin_theta, ring_of_orbit, alpha, partial, order):  # pragma: no cover (compiled)
    """(order, order, 2C) array: [m, l] holds sum over rings of P~_lm(theta_r) S_m(r), real and imaginary
    parts per channel, with S_m(r) = sum over the orbits o of ring r of e^{i m alpha_o} a_o + e^{-i m alpha_o} b_o
    and partial[0 or 1, m mod 4, o] = a_o or b_o (see sh._Orbits)."""
    n_rings = cos_theta.size
    n_orbits = alpha.size
    channels = partial.shape[3]
    out = np.zeros((order, order, 2 * channels))
    perm = _interleaved(order)
    for k in numba.prange(order):
        m = perm[k]
        r4 = m % 4
        sums = np.zeros((2 * channels, n_rings))
        for o in range(n_orbits):
            c = math.cos(m * alpha[o])
            s = math.sin(m * alpha[o])
            r = ring_of_orbit[o]
            for ch in range(channels):
                a = partial[0, r4, o, ch]
                b = partial[1, r4, o, ch]
                sums[2 * ch, r] += c * (a.real + b.real) - s * (a.imag - b.imag)  # z a + conj(z) b
                sums[2 * ch + 1, r] += c * (a.imag + b.imag) + s * (a.real - b.real)
        n_l = order - m
        ca, cab, pmm_factor, start1 = _recurrence(m, order)
        acc = np.zeros((n_l, 2 * channels))
        p0 = np.empty(RING_BLOCK)
        p1 = np.empty(RING_BLOCK)
        for r0 in range(0, n_rings, RING_BLOCK):
            nb = min(RING_BLOCK, n_rings - r0)
            x = cos_theta[r0:r0 + nb]
            rs = sums[:, r0:r0 + nb]
            for b in range(nb):
                p0[b] = pmm_factor * (-sin_theta[r0 + b]) ** m
            for q in range(2 * channels):
                t = 0.0
                for b in range(nb):
                    t += p0[b] * rs[q, b]
                acc[0, q] += t
            if n_l > 1:
                for b in range(nb):
                    p1[b] = start1 * x[b] * p0[b]
                for q in range(2 * channels):
                    t = 0.0
                    for b in range(nb):
                        t += p1[b] * rs[q, b]
                    acc[1, q] += t
            for j in range(2, n_l):
                a = ca[j]
                ab = cab[j]
                for b in range(nb):
                    v = a * x[b] * p1[b] - ab * p0[b]
                    p0[b] = p1[b]
                    p1[b] = v
                for q in range(2 * channels):
                    t = 0.0
                    for b in range(nb):
                        t += p1[b] * rs[q, b]
                    acc[j, q] += t
        for j in range(n_l):
            for q in range(2 * channels):
                out[m, m + j, q] = acc[j, q]
    return out


@numba.njit(parallel=True, cache=True)
def bilinear_lookup(texels, index, weight):  # pragma: no cover (compiled)
    """(K, C): sum over the four corners c of weight[k, c] texels[index[k, c]], texels being (P, C)."""
    n_out = index.shape[0]
    channels = texels.shape[1]
    out = np.zeros((n_out, channels))
    for k in numba.prange(n_out):
        for c in range(4):
            w = weight[k, c]
            row = index[k, c]
            for ch in range(channels):
                out[k, ch] += w * texels[row, ch]
    return out


@numba.njit(parallel=True, cache=True)
def lookup_channels(grid, index, weight):  # pragma: no cover (compiled)
    """(K, C): sum over the four corners j of weight[k, j] grid[c, index[k, j]], grid being (C, P) (each
    channel's plane as ducc0 writes it, no transpose)."""
    channels = grid.shape[0]
    out = np.empty((index.shape[0], channels))
    for k in numba.prange(index.shape[0]):
        for ch in range(channels):
            v = 0.0
            for j in range(4):
                v += weight[k, j] * grid[ch, index[k, j]]
            out[k, ch] = v
    return out


@numba.njit(inline="always")
def _catmull_rom(t):  # pragma: no cover (compiled)
    t2 = t * t
    t3 = t2 * t
    return (0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + t),
            0.5 * (t3 - t2))


@numba.njit(parallel=True, cache=True, fastmath=True)
def cubic_lookup_into(out, texel_index, grid, n_theta, n_phi, rows, cols, den):  # pragma: no cover (compiled)
    """out[texel_index[k], c] = the Catmull-Rom (bicubic) value of the (C <= 3, n_theta * n_phi) grid at fractional
    (rows[k], cols[k]), divided by den[k] (0 where den[k] <= 0). Rows past a pole continue on the far side
    of it (row -r is row r half a turn round), columns wrap. Away from the poles and the seam a row's four
    columns are contiguous and read without a modulo (1.8x faster; the same sums in the same order)."""
    channels = grid.shape[0]
    half = n_phi // 2
    # Three channels read (1 or 3 in use; a single channel is read thrice).
    g0, g1, g2 = grid[0], grid[min(1, channels - 1)], grid[min(2, channels - 1)]
    for k in numba.prange(rows.size):
        r0 = int(math.floor(rows[k]))
        c0 = int(math.floor(cols[k]))
        wr = _catmull_rom(rows[k] - r0)
        wc = _catmull_rom(cols[k] - c0)
        near_pole = r0 < 1 or r0 + 2 > n_theta - 1
        a0 = a1 = a2 = 0.0
        for i in range(4):
            r = r0 - 1 + i
            shift = 0
            if near_pole:
                if r < 0:
                    r = -r
                    shift = half
                elif r > n_theta - 1:
                    r = 2 * (n_theta - 1) - r
                    shift = half
            base = r * n_phi
            first = c0 - 1 + shift
            if first >= 0 and first + 3 < n_phi:
                q = base + first
                b0 = wc[0] * g0[q] + wc[1] * g0[q + 1] + wc[2] * g0[q + 2] + wc[3] * g0[q + 3]
                b1 = wc[0] * g1[q] + wc[1] * g1[q + 1] + wc[2] * g1[q + 2] + wc[3] * g1[q + 3]
                b2 = wc[0] * g2[q] + wc[1] * g2[q + 1] + wc[2] * g2[q + 2] + wc[3] * g2[q + 3]
            else:
                b0 = b1 = b2 = 0.0
                for j in range(4):
                    q = base + (first + j) % n_phi
                    b0 += wc[j] * g0[q]
                    b1 += wc[j] * g1[q]
                    b2 += wc[j] * g2[q]
            a0 += wr[i] * b0
            a1 += wr[i] * b1
            a2 += wr[i] * b2
        inverse = 1.0 / den[k] if den[k] > 0 else 0.0
        t = texel_index[k]
        out[t, 0] = a0 * inverse
        if channels > 1:
            out[t, 1] = a1 * inverse
        if channels > 2:
            out[t, 2] = a2 * inverse


@numba.njit(parallel=True, cache=True, fastmath=True)
def ring_series(legendre, first, weights, ring_start, cos_phi, sin_phi, texel, out):  # pragma: no cover (compiled)
    """The low-order SH series of E maps at the texels, ring by ring of equal polar angle. Per ring r and map e,
    its Legendre sums radial[e, j, c, m] = sum_l legendre[r, first[m] + l - m] weights[e, j, c, first[m] + l - m]
    (j = 0: the cos term of m, 1: the sin term), kept in a small buffer; then per texel k of the ring (texels
    sorted by ring, ring r's from ring_start[r] to ring_start[r + 1]) out[e, texel[k], c] = sum_m
    radial[e, 0, c, m] cos(m phi_k) + radial[e, 1, c, m] sin(m phi_k), cos and sin of m phi by the
    angle-addition recurrence. legendre (rings, order (order + 1) / 2): the orthonormal P_lm packed m by m
    (first[m]: where m's start). Every map in one pass: a ring's Legendre row is read once and its texels'
    recurrence runs once for all of them (nine maps at order 16: 0.10 s against 0.16-0.18 s map by map)."""
    order = first.size - 1
    n_maps, _, channels, _ = weights.shape
    for r in numba.prange(ring_start.size - 1):
        radial = np.empty((n_maps, 2, channels, order))
        row = legendre[r]
        for e in range(n_maps):
            for j in range(2):
                for c in range(channels):
                    w = weights[e, j, c]
                    for m in range(order):
                        total = 0.0
                        for i in range(first[m], first[m + 1]):
                            total += row[i] * w[i]
                        radial[e, j, c, m] = total
        # The ring's texels side by side (m outermost): each step of the recurrence and of the sums runs over
        # them at once, in vector lanes, rather than as a chain of dependent steps per texel.
        k0, k1 = ring_start[r], ring_start[r + 1]
        count = k1 - k0
        c1, s1 = cos_phi[k0:k1], sin_phi[k0:k1]
        cos_m, sin_m = np.ones(count), np.zeros(count)
        totals = np.zeros((n_maps, channels, count))
        for m in range(order):
            if m > 0:
                for i in range(count):
                    cos_next = cos_m[i] * c1[i] - sin_m[i] * s1[i]
                    sin_m[i] = sin_m[i] * c1[i] + cos_m[i] * s1[i]
                    cos_m[i] = cos_next
            for e in range(n_maps):
                for c in range(channels):
                    a, b = radial[e, 0, c, m], radial[e, 1, c, m]
                    t = totals[e, c]
                    for i in range(count):
                        t[i] += a * cos_m[i] + b * sin_m[i]
        for e in range(n_maps):
            for i in range(count):
                for c in range(channels):
                    out[e, texel[k0 + i], c] = totals[e, c, i]
