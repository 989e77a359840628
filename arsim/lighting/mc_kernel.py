"""The compiled heart of `mc`: per texel, its importance samples drawn about its direction, mapped into
the angle map, filtered by their level of detail and read trilinearly from the MIP chain -- the same
arithmetic as mc.py's NumPy path (sample_phong_lobe, direction_to_anglemap_st, sample_trilinear) with
the same uniforms, on every core, without the (texels x samples) temporaries. The NumPy path stays
as its reference in the tests."""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(inline="always")
def _bilinear(flat, offset, size, row, col):  # pragma: no cover (compiled)
    """The bilinear RGB of the level (size x size x 3, at flat[offset:]) at (row, col), clamped to the
    edge (scipy's map_coordinates, order 1, mode 'nearest')."""
    r0 = math.floor(row)
    c0 = math.floor(col)
    fr = row - r0
    fc = col - c0
    ra = min(max(r0, 0), size - 1)
    rb = min(max(r0 + 1, 0), size - 1)
    ca = min(max(c0, 0), size - 1)
    cb = min(max(c0 + 1, 0), size - 1)
    i00 = offset + (ra * size + ca) * 3
    i01 = offset + (ra * size + cb) * 3
    i10 = offset + (rb * size + ca) * 3
    i11 = offset + (rb * size + cb) * 3
    w00 = (1.0 - fr) * (1.0 - fc)
    w01 = (1.0 - fr) * fc
    w10 = fr * (1.0 - fc)
    w11 = fr * fc
    r = w00 * flat[i00] + w01 * flat[i01] + w10 * flat[i10] + w11 * flat[i11]
    g = w00 * flat[i00 + 1] + w01 * flat[i01 + 1] + w10 * flat[i10 + 1] + w11 * flat[i11 + 1]
    b = w00 * flat[i00 + 2] + w01 * flat[i01 + 2] + w10 * flat[i10 + 2] + w11 * flat[i11 + 2]
    return r, g, b


@numba.njit(parallel=True, cache=True, error_model="numpy")
def mc_values(dirs, u1, u2, exponent, flat, offsets, sizes, texel_solid_angle, lod_bias, filtered):  # pragma: no cover
    """(K, 3) lobe averages: the mean over S samples of texel k, uniforms u1[k], u2[k] (K, S)."""
    n_dirs, samples = u1.shape
    n_levels = sizes.size
    out = np.zeros((n_dirs, 3))
    for k in numba.prange(n_dirs):
        dx, dy, dz = dirs[k, 0], dirs[k, 1], dirs[k, 2]
        if abs(dz) < 0.9:
            hx, hy, hz = 0.0, 0.0, 1.0
        else:
            hx, hy, hz = 1.0, 0.0, 0.0
        tx, ty, tz = hy * dz - hz * dy, hz * dx - hx * dz, hx * dy - hy * dx  # cross(helper, d)
        norm = math.sqrt(tx * tx + ty * ty + tz * tz)
        tx, ty, tz = tx / norm, ty / norm, tz / norm
        bx, by, bz = dy * tz - dz * ty, dz * tx - dx * tz, dx * ty - dy * tx  # cross(d, t)
        acc_r = acc_g = acc_b = 0.0
        for j in range(samples):
            cos_t = u1[k, j] ** (1.0 / (exponent + 1.0))
            sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
            phi = 2.0 * math.pi * u2[k, j]
            a = sin_t * math.cos(phi)
            b = sin_t * math.sin(phi)
            wx = a * tx + b * bx + cos_t * dx
            wy = a * ty + b * by + cos_t * dy
            wz = a * tz + b * bz + cos_t * dz
            pdf = (exponent + 1.0) / (2.0 * math.pi) * cos_t**exponent
            rad = math.hypot(wx, wy)
            ang = math.atan2(rad, wz)
            if rad > 0:
                s = 0.5 + 0.5 * (wx / rad) * (ang / math.pi)
                t = 0.5 + 0.5 * (wy / rad) * (ang / math.pi)
            elif wz < 0:
                s, t = 0.5, 1.0  # the rim point (conventions.ANGLEMAP_RIM_ST)
            else:
                s, t = 0.5, 0.5
            lod = 0.0
            if filtered:
                rho = math.hypot(2.0 * s - 1.0, 2.0 * t - 1.0)
                sinc = math.sin(math.pi * rho) / (math.pi * rho) if rho != 0 else 1.0
                omega_p = texel_solid_angle * max(sinc, 1e-6)
                omega_s = 1.0 / (samples * pdf)
                lod = max(0.5 * math.log2(omega_s / omega_p) + lod_bias, 0.0)
            lod = min(max(lod, 0.0), n_levels - 1.0)
            lower = int(math.floor(lod))
            frac = lod - lower
            upper = min(lower + 1, n_levels - 1)
            if 1.0 - frac > 0:
                size = sizes[lower]
                r, g, b = _bilinear(flat, offsets[lower], size, (1.0 - t) * size - 0.5, s * size - 0.5)
                acc_r += (1.0 - frac) * r
                acc_g += (1.0 - frac) * g
                acc_b += (1.0 - frac) * b
            if frac > 0:
                size = sizes[upper]
                r, g, b = _bilinear(flat, offsets[upper], size, (1.0 - t) * size - 0.5, s * size - 0.5)
                acc_r += frac * r
                acc_g += frac * g
                acc_b += frac * b
        out[k, 0] = acc_r / samples
        out[k, 1] = acc_g / samples
        out[k, 2] = acc_b / samples
    return out
