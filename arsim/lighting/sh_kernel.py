"""Compiled loops of the SH maps: the ring sums times associated Legendre functions for every (l, m), which
compute `sh_coefficients` up to sh.RINGS_MAX_ORDER (ducc0's adjoint transform beyond), the low orders' series
at the texels (orbit_series), and the grid lookups of sh.py and sht.py.

Coefficients: the texels' partial sums per symmetry orbit (orbit_partials); per m, the azimuthal sums of each
ring are gathered from its orbits' partial sums, then the orthonormal
Legendre recurrence runs over the rings in blocks small enough for the first-level cache, with the
projections accumulated as it goes, so that the (order^2/2 x rings) Legendre table is never stored.
Threads take whole m values (numba prange), large and small m interleaved so the shares are equal.
The NumPy path in sh.py computes the same sums (up to rounding) and is the reference in the tests.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from arsim.core.simd import accumulate_texels

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


@numba.njit(parallel=True, cache=True)
def orbit_partials(lw, orbit_texels, texel, sigma, quarter):  # pragma: no cover (compiled)
    """(2, 4, O, C) complex: per orbit o, per side (0: sigma = +1, 1: -1) and r = m mod 4, the sum of lw[t] i^(r k)
    over its texels t with that sigma (k their quarter turns): what sh._sh_coefficients_rings sums with NumPy's
    bincounts. Texels orbit_texels[o] .. orbit_texels[o + 1] - 1 (texel[j]: the row of lw) make orbit o; each
    orbit is summed by one thread, its texels in a fixed order, so the sums do not depend on the threads."""
    n_orbits = orbit_texels.size - 1
    channels = lw.shape[1]
    out = np.zeros((2, 4, n_orbits, channels), dtype=np.complex128)
    for o in numba.prange(n_orbits):
        for j in range(orbit_texels[o], orbit_texels[o + 1]):
            side = 0 if sigma[j] > 0 else 1
            k = quarter[j]
            t = texel[j]
            for r in range(4):
                turn = (r * k) % 4  # i^turn: 1, i, -1, -i
                for ch in range(channels):
                    v = lw[t, ch]
                    if turn == 0:
                        out[side, r, o, ch] += v
                    elif turn == 1:
                        out[side, r, o, ch] += 1j * v
                    elif turn == 2:
                        out[side, r, o, ch] -= v
                    else:
                        out[side, r, o, ch] -= 1j * v
    return out


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


@numba.njit(inline="always")
def _store_colour(maps, which, pixel, red, green, blue, den, normalise):  # pragma: no cover (compiled)
    """A texel's colour into the float32 maps (E, N * N, 3) as sh.sh_maps writes it: with normalise divided by den,
    the lobe's sum of the texel weights (0 where that is not positive)."""
    if normalise:
        if den > 0.0:
            red, green, blue = red / den, green / den, blue / den
        else:
            red = green = blue = 0.0
    maps[which, pixel, 0] = red
    maps[which, pixel, 1] = green
    maps[which, pixel, 2] = blue


@numba.njit(parallel=True, cache=True)
def lookup_channels_into(maps, which, texel, grid, index, weight, normalise):  # pragma: no cover (compiled)
    """maps[which, texel[k], c] = sum over the four corners j of weight[k, j] grid[c, index[k, j]] for c < 3, grid
    being (C, P) (each channel's plane as ducc0 writes it, no transpose; one colour channel is read into all three);
    with normalise divided by the same sum of its last channel (_store_colour). Straight into the (E, N * N, 3)
    float32 maps: no (K, C) values stacked and scattered after."""
    colour = grid.shape[0] - (1 if normalise else 0)  # (one channel: a grey map, read into all three)
    c1, c2 = min(1, colour - 1), min(2, colour - 1)
    for k in numba.prange(index.shape[0]):
        v0 = v1 = v2 = v3 = 0.0
        for j in range(4):
            w, q = weight[k, j], index[k, j]
            v0 += w * grid[0, q]
            v1 += w * grid[c1, q]
            v2 += w * grid[c2, q]
            if normalise:
                v3 += w * grid[colour, q]
        _store_colour(maps, which, texel[k], v0, v1, v2, v3, normalise)


@numba.njit(inline="always")
def _catmull_rom(t):  # pragma: no cover (compiled)
    t2 = t * t
    t3 = t2 * t
    return (0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0), 0.5 * (-3.0 * t3 + 4.0 * t2 + t),
            0.5 * (t3 - t2))


@numba.njit(parallel=True, cache=True, fastmath=True)
def cubic_lookup_into(out, texel_index, grid, n_theta, n_phi, rows, cols, den):  # pragma: no cover (compiled)
    """out[texel_index[k], c] = the Catmull-Rom (bicubic) value of the grid at fractional (rows[k], cols[k]),
    divided by den[k] (0 where den[k] <= 0), for the C = out.shape[1] <= 3 channels. The grid is RGBA float32,
    flat (n_theta * n_phi * 4: rgba_grid), so that each of a row's four taps is one vector read and multiply-add
    (core.simd). Rows past a pole continue on the far side of it (row -r is row r half a turn round), columns
    wrap."""
    channels = out.shape[1]
    half = n_phi // 2
    zero = np.float32(0.0)
    for k in numba.prange(rows.size):
        r0 = int(math.floor(rows[k]))
        c0 = int(math.floor(cols[k]))
        wr = _catmull_rom(rows[k] - r0)
        wc = _catmull_rom(cols[k] - c0)
        near_pole = r0 < 1 or r0 + 2 > n_theta - 1
        acc = (zero, zero, zero, zero)
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
            w = wr[i]
            weights = (np.float32(w * wc[0]), np.float32(w * wc[1]), np.float32(w * wc[2]), np.float32(w * wc[3]))
            if first >= 0 and first + 3 < n_phi:  # (away from the poles and the seam: no modulo)
                q = base + first
                acc = accumulate_texels(acc, grid, (q, q + 1, q + 2, q + 3), weights)
            else:
                acc = accumulate_texels(acc, grid, (base + first % n_phi, base + (first + 1) % n_phi,
                                                    base + (first + 2) % n_phi, base + (first + 3) % n_phi), weights)
        inverse = 1.0 / den[k] if den[k] > 0 else 0.0
        t = texel_index[k]
        out[t, 0] = acc[0] * inverse
        if channels > 1:
            out[t, 1] = acc[1] * inverse
        if channels > 2:
            out[t, 2] = acc[2] * inverse


def rgba_grid(n_theta: int, n_phi: int) -> np.ndarray:
    """A zeroed (n_theta, n_phi, 4) float32 grid for cubic_lookup_into (channels written through its [..., c]
    views; the fourth lane pads each point to one vector)."""
    return np.zeros((n_theta, n_phi, 4), dtype=np.float32)


@numba.njit(parallel=True, cache=True, fastmath=True)
def orbit_series(legendre, first, weights, ring_orbits, cos_alpha, sin_alpha, orbit_texels, texel, sigma, quarter,
                 maps, which, channels, normalise):  # pragma: no cover (compiled)
    """The low-order SH series of several maps and channels (a column each: W of them) at the disk texels,
    ring by ring of equal polar angle and, within a ring, orbit by orbit of the square grid's symmetry
    (sh._Orbits).

    Per ring r, its Legendre sums A[m, x] = sum_l legendre[r, first[m] + l - m] weights[0, first[m] + l - m, x]
    (the cos terms of m) and B[m, x] from weights[1] (the sin terms); legendre (rings, order (order + 1) / 2)
    holds the orthonormal P_lm packed m by m (first[m]: where m's start), and the columns x run innermost, in
    vector lanes. A texel's value is sum_m A_m cos(m phi) + B_m sin(m phi) = Re sum_m (A_m - i B_m) e^{i m phi},
    and its azimuth is phi = sigma alpha + k pi / 2 with alpha its orbit's angle: e^{i m phi} = (cos m alpha +
    i sigma sin m alpha) i^(m k). So each orbit sums, per class q = m mod 4, P = sum A cos, Q = sum B sin,
    R = sum A sin and T = sum B cos once (cos and sin of m alpha by the angle-addition recurrence), and each of its
    up to eight texels combines them: with U_q = P_q + sigma Q_q and V_q = T_q - sigma R_q, the value is
    U_0 + U_1 + U_2 + U_3 (k = 0), U_0 + V_1 - U_2 - V_3 (1), U_0 - U_1 + U_2 - U_3 (2) or U_0 - V_1 - U_2 + V_3 (3).
    Orbits ring_orbits[r] .. ring_orbits[r + 1] - 1 make ring r; texels orbit_texels[o] .. orbit_texels[o + 1] - 1
    (texel[j]: its index in the N x N map, sigma[j] = +-1, quarter[j] = k) make orbit o.

    The columns are the maps' channels, map e's from e C (with normalise, the last is the lobe's sum of the
    texel weights, which divides the others; one colour channel makes a grey map); a texel's three colours go
    straight into maps[which[e], texel[j]] (_store_colour)."""
    order = first.size - 1
    width = weights.shape[2]
    colour = channels - (1 if normalise else 0)  # (one channel: a grey map, written into all three)
    n_rings = ring_orbits.size - 1
    chunks = min(n_rings, 256)  # (each chunk of rings allocates its buffers once)
    for chunk in numba.prange(chunks):
        radial = np.empty((2, order, width))
        sums = np.empty((4, 4, width))  # [q, (P, Q, R, T), x]
        combined = np.empty((2, 2, 4, width))  # [sigma +1 / -1, (U, V), q, x]
        target = np.empty(width)
        for r in range(chunk * n_rings // chunks, (chunk + 1) * n_rings // chunks):
            radial[:] = 0.0
            for j in range(2):
                for m in range(order):
                    for i in range(first[m], first[m + 1]):
                        p = legendre[r, i]
                        for x in range(width):
                            radial[j, m, x] += p * weights[j, i, x]
            for o in range(ring_orbits[r], ring_orbits[r + 1]):
                sums[:] = 0.0
                c1, s1 = cos_alpha[o], sin_alpha[o]
                cos_m, sin_m = 1.0, 0.0
                for m in range(order):
                    if m > 0:
                        cos_m, sin_m = cos_m * c1 - sin_m * s1, sin_m * c1 + cos_m * s1
                    q = m & 3
                    for x in range(width):
                        a, b = radial[0, m, x], radial[1, m, x]
                        sums[q, 0, x] += a * cos_m
                        sums[q, 1, x] += b * sin_m
                        sums[q, 2, x] += a * sin_m
                        sums[q, 3, x] += b * cos_m
                for q in range(4):
                    for x in range(width):
                        combined[0, 0, q, x] = sums[q, 0, x] + sums[q, 1, x]
                        combined[0, 1, q, x] = sums[q, 3, x] - sums[q, 2, x]
                        combined[1, 0, q, x] = sums[q, 0, x] - sums[q, 1, x]
                        combined[1, 1, q, x] = sums[q, 3, x] + sums[q, 2, x]
                for j in range(orbit_texels[o], orbit_texels[o + 1]):
                    g = 0 if sigma[j] > 0 else 1
                    turn = quarter[j]
                    if turn == 0:
                        for x in range(width):
                            target[x] = (combined[g, 0, 0, x] + combined[g, 0, 1, x]
                                         + combined[g, 0, 2, x] + combined[g, 0, 3, x])
                    elif turn == 1:
                        for x in range(width):
                            target[x] = (combined[g, 0, 0, x] + combined[g, 1, 1, x]
                                         - combined[g, 0, 2, x] - combined[g, 1, 3, x])
                    elif turn == 2:
                        for x in range(width):
                            target[x] = (combined[g, 0, 0, x] - combined[g, 0, 1, x]
                                         + combined[g, 0, 2, x] - combined[g, 0, 3, x])
                    else:
                        for x in range(width):
                            target[x] = (combined[g, 0, 0, x] - combined[g, 1, 1, x]
                                         - combined[g, 0, 2, x] + combined[g, 1, 3, x])
                    for e in range(which.size):
                        base = e * channels
                        _store_colour(maps, which[e], texel[j], target[base], target[base + min(1, colour - 1)],
                                      target[base + min(2, colour - 1)], target[base + channels - 1], normalise)
