"""The compiled heart of `mc`: per texel, its sample pattern turned about its direction, mapped into
the angle map, filtered by its level of detail and read trilinearly from the MIP chain (bordered
levels, mc.bordered_chain) -- the same
arithmetic as mc.py's NumPy path (sample_phong_lobe, direction_to_anglemap_st, sample_trilinear) with
the same sample pattern, every exponent in one pass per texel, on every core, without (texels x
samples) temporaries. The NumPy path stays as its reference in the tests.

What depends only on a sample's place in the pattern (its cos theta, its azimuth's cosine and sine, the
part of its level of detail that its pdf sets) is tabulated once per exponent (mc.pattern_tables); per
sample there remain a rotation, one atan2, one log2 and two bilinear reads of a float32 RGBA chain, each
four vector reads (core.simd)."""

from __future__ import annotations

import math

import numba
import numpy as np

from arsim.core.simd import accumulate_texels


# atan(a) = a * P(a^2) on [0, 1], least squares on Chebyshev nodes: 6e-9 rad at most (a 512² map's
# texel spans 1.2e-2 rad), a fifth of libm's atan2 time, no branches.
_ATAN = (0.99999991, -0.33332658, 0.19986536, -0.14164325, 0.10507289, -0.07247887, 0.03989882, -0.01445824,
         0.00246813)


@numba.njit(inline="always")
def _atan2_upper(y, x):  # pragma: no cover (compiled)
    """atan2(y, x) for y >= 0, (x, y) != 0, within 6e-9 rad."""
    ax = abs(x)
    a = min(y, ax) / max(y, ax)
    a2 = a * a
    p = _ATAN[8]
    p = p * a2 + _ATAN[7]
    p = p * a2 + _ATAN[6]
    p = p * a2 + _ATAN[5]
    p = p * a2 + _ATAN[4]
    p = p * a2 + _ATAN[3]
    p = p * a2 + _ATAN[2]
    p = p * a2 + _ATAN[1]
    p = p * a2 + _ATAN[0]
    p *= a
    if y > ax:
        p = 0.5 * math.pi - p
    if x < 0:
        p = math.pi - p
    return p


@numba.njit(inline="always")
def _level_texel(size, offset, s, t):  # pragma: no cover (compiled)
    """Where a bilinear read at texture coordinates (s, t) starts in a bordered level of side `size` whose
    texels begin at `offset` of the flat chain: its flat texel index, the row stride and the fractions down a
    row and along it. Rows and columns in the bordered level (+1) are >= 0.5, so truncation is floor."""
    row = (1.0 - t) * size + 0.5
    col = s * size + 0.5
    r0, c0 = int(row), int(col)
    return offset + r0 * (size + 2) + c0, size + 2, row - r0, col - c0


@numba.njit(inline="always")
def _bilinear_at(flat, at, stride, fr, fc):  # pragma: no cover (compiled)
    """The bilinear RGBA of texels at, at + 1, at + stride, at + stride + 1 (flat index in texels) with
    fractions fr (down a row) and fc (along it): four vector reads (core.simd). The levels' copied border makes
    this clamp-to-edge, scipy's map_coordinates (order 1, mode 'nearest') on the level itself."""
    one, zero = np.float32(1.0), np.float32(0.0)
    return accumulate_texels((zero, zero, zero, zero), flat, (at, at + 1, at + stride, at + stride + 1),
                             ((one - fr) * (one - fc), (one - fr) * fc, fr * (one - fc), fr * fc))


@numba.njit(parallel=True, cache=True, error_model="numpy", fastmath=True)
def mc_values(dirs, turns, cos_t, along_t, along_b, lod_base, flat, offsets, sizes, filtered):  # pragma: no cover
    """(E, K, 3) lobe averages of texels dirs (K, 3): exponent e's pattern (tables (E, S)) turned by
    turns[e, k] radians about texel k's direction; lod_base[e, j] is sample j's level of detail less
    -0.5 log2(sinc) of where it lands (mc.pattern_tables).

    Per texel and exponent, one loop places all samples (s, t, level of detail) and a second reads
    them: the samples are independent, so the core overlaps their latencies instead of waiting on
    each sample's chain of sqrt, divisions, polynomial and loads."""
    n_exp, samples = cos_t.shape
    n_dirs = dirs.shape[0]
    n_levels = sizes.size
    top = n_levels - 1.0
    out = np.zeros((n_exp, n_dirs, 3))
    half_inv_pi = 0.5 / math.pi
    for k in numba.prange(n_dirs):
        ss = np.empty(samples)
        tt = np.empty(samples)
        ll = np.empty(samples)
        mant = np.empty(samples, dtype=np.int64)
        at_lo = np.empty(samples, dtype=np.int64)
        at_hi = np.empty(samples, dtype=np.int64)
        stride_lo = np.empty(samples, dtype=np.int64)
        stride_hi = np.empty(samples, dtype=np.int64)
        fr_lo = np.empty(samples, dtype=np.float32)
        fc_lo = np.empty(samples, dtype=np.float32)
        fr_hi = np.empty(samples, dtype=np.float32)
        fc_hi = np.empty(samples, dtype=np.float32)
        ll_bits = ll.view(np.int64)
        mant_float = mant.view(np.float64)
        dx, dy, dz = dirs[k, 0], dirs[k, 1], dirs[k, 2]
        if abs(dz) < 0.9:
            hx, hy, hz = 0.0, 0.0, 1.0
        else:
            hx, hy, hz = 1.0, 0.0, 0.0
        tx, ty, tz = hy * dz - hz * dy, hz * dx - hx * dz, hx * dy - hy * dx  # cross(helper, d)
        norm = math.sqrt(tx * tx + ty * ty + tz * tz)
        tx, ty, tz = tx / norm, ty / norm, tz / norm
        bx, by, bz = dy * tz - dz * ty, dz * tx - dx * tz, dx * ty - dy * tx  # cross(d, t)
        for e in range(n_exp):
            # The pattern turned by the texel's angle: azimuth phi_j + turn = the frame turned by it.
            c, s_ = math.cos(turns[e, k]), math.sin(turns[e, k])
            ux, uy, uz = c * tx + s_ * bx, c * ty + s_ * by, c * tz + s_ * bz
            vx, vy, vz = c * bx - s_ * tx, c * by - s_ * ty, c * bz - s_ * tz
            for j in range(samples):  # branch-free: the compiler can run it in SIMD lanes
                a = along_t[e, j]
                b = along_b[e, j]
                ct = cos_t[e, j]
                wx = a * ux + b * vx + ct * dx
                wy = a * uy + b * vy + ct * dy
                wz = a * uz + b * vz + ct * dz
                rad = math.sqrt(wx * wx + wy * wy)
                ang = _atan2_upper(rad, wz)  # 0 at +z, pi at -z
                scale = ang * half_inv_pi / max(rad, 1e-300)
                ss[j] = 0.5 + wx * scale
                # at -z (rad = 0) the rim point (conventions.ANGLEMAP_RIM_ST), at +z the centre
                tt[j] = 0.5 + wy * scale if rad > 0 else (1.0 if wz < 0 else 0.5)
                ll[j] = max(rad / ang if ang > 0 else 1.0, 1e-6)  # sinc, for the lookup's Omega_p
            if filtered:
                # lod = base - 0.5 log2(sinc), log2 from the float's bits: exponent + log2 of the
                # mantissa m in [1, 2) as 2/ln 2 atanh((m - 1)/(m + 1)), 7 terms, within 5e-9.
                for j in range(samples):
                    mant[j] = (ll_bits[j] & 0xFFFFFFFFFFFFF) | 0x3FF0000000000000
                for j in range(samples):
                    ex = (ll_bits[j] >> 52) - 1023
                    m = mant_float[j]
                    z = (m - 1.0) / (m + 1.0)
                    z2 = z * z
                    series = 1.0 + z2 * (1.0 / 3 + z2 * (1.0 / 5 + z2 * (1.0 / 7 + z2 * (1.0 / 9 + z2 * (1.0 / 11 + z2 / 13)))))
                    log2_sinc = ex + 2.0 / math.log(2.0) * z * series
                    ll[j] = min(max(lod_base[e, j] - 0.5 * log2_sinc, 0.0), top)
            else:
                for j in range(samples):
                    ll[j] = 0.0
            for j in range(samples):  # where each sample's two levels are read, and with what weights
                lod = ll[j]
                lower = int(lod)
                frac = lod - lower
                upper = min(lower + 1, n_levels - 1)
                at_lo[j], stride_lo[j], fr_lo[j], fc_lo[j] = _level_texel(sizes[lower], offsets[lower], ss[j], tt[j])
                at_hi[j], stride_hi[j], fr_hi[j], fc_hi[j] = _level_texel(sizes[upper], offsets[upper], ss[j], tt[j])
                ll[j] = frac
            acc_r = acc_g = acc_b = 0.0
            for j in range(samples):  # the reads: independent, so their latencies overlap
                r, g, bl, _ = _bilinear_at(flat, at_lo[j], stride_lo[j], fr_lo[j], fc_lo[j])
                frac = ll[j]
                if frac > 0:
                    r2, g2, b2, _ = _bilinear_at(flat, at_hi[j], stride_hi[j], fr_hi[j], fc_hi[j])
                    r += frac * (r2 - r)
                    g += frac * (g2 - g)
                    bl += frac * (b2 - bl)
                acc_r += r
                acc_g += g
                acc_b += bl
            out[e, k, 0] = acc_r / samples
            out[e, k, 1] = acc_g / samples
            out[e, k, 2] = acc_b / samples
    return out
