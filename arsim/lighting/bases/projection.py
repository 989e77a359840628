"""Projection of hemispherical signals into a basis (numerical integration over the hemisphere), the
reconstruction, and the closed-form projections from nine SH coefficients that the specs give.

A projection is the least-squares fit over the hemisphere: c = G^-1 b with b_i = int B_i f and G the Gram
matrix. For an orthonormal basis G = I and c_i = int B_i f; for the modified H-basis and for SH (not
orthogonal over the hemisphere) G^-1 makes it the best fit all the same.
"""

from __future__ import annotations

from functools import cache, lru_cache
from math import log, pi, sqrt

import numpy as np

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles
from arsim.lighting.bases.functions import Basis, get_basis, sh9
from arsim.lighting.bases.quadrature import hemisphere_quadrature


@lru_cache(maxsize=4)
def disk_geometry(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An N x N angle map's disk mask, its texels' directions (K, 3) and solid angles (K,), computed once a
    size (a light estimate a frame must not pay for them; read-only)."""
    inside = anglemap_disk_mask(n)
    arrays = inside, anglemap_directions(n)[inside], anglemap_solid_angles(n)[inside]
    for a in arrays:
        a.flags.writeable = False
    return arrays


def disk_samples(anglemap: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An angle map's disk texels as samples of the sphere: directions (K, 3), radiance (K, 3), solid angles (K,)."""
    inside, d, omega = disk_geometry(anglemap.shape[0])
    return d, np.asarray(anglemap, dtype=np.float64)[inside][:, :3], omega


def sh_radiance(anglemap: np.ndarray) -> np.ndarray:
    """(9, 3): the radiance's coefficients L_lm in the real orthonormal SH basis of bands 0-2 (sh9: no
    Condon-Shortley phase, order (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1), (2,0), (2,1), (2,2), of the world
    direction (x, y, z), +y up), so that the irradiance is E(n) = sum A_l L_lm Y_lm(n), A_l = pi, 2 pi / 3, pi / 4:
    the sum over the angle map's disk texels with their solid angles, in float64."""
    d, radiance, omega = disk_samples(anglemap)
    return sh9(d).T @ (radiance * omega[:, None])


@cache
def _quadrature() -> tuple[np.ndarray, np.ndarray]:
    return hemisphere_quadrature()


def gram(basis: Basis, count: int) -> np.ndarray:
    """(count, count): int over the upper hemisphere of B_i B_j."""
    d, w = _quadrature()
    b = basis.evaluate(d, count)
    return (b * w[:, None]).T @ b


def project(basis: Basis, count: int, values: np.ndarray, directions: np.ndarray | None = None,
            weights: np.ndarray | None = None) -> np.ndarray:
    """Coefficients (count, C) of the least-squares fit of a signal over the upper hemisphere, given its
    values (K, C) (or (K,)) at quadrature directions with their weights (default: this module's rule)."""
    if directions is None:
        directions, weights = _quadrature()
    values = np.asarray(values, dtype=np.float64)
    flat = values.reshape(len(directions), -1)
    b = basis.evaluate(directions, count)
    moments = (b * weights[:, None]).T @ flat
    coeffs = moments if basis.orthonormal else np.linalg.solve(gram(basis, count), moments)
    return coeffs.reshape((count,) + values.shape[1:])


def reconstruct(basis: Basis, count: int, coeffs: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """sum_i c_i B_i at directions (..., 3): (..., C) (or (...) for coefficients (count,))."""
    return np.tensordot(basis.evaluate(directions, count), coeffs, axes=([-1], [0]))


def from_sh9_matrix(basis: Basis, count: int) -> np.ndarray:
    """(count, 9): the basis's coefficients of the hemispherical least-squares fit of sum_j s_j Y_j (spec
    SH order, no Condon-Shortley phase), computed by integration."""
    d, w = _quadrature()
    b = basis.evaluate(d, count)
    moments = (b * w[:, None]).T @ sh9(d)
    return moments if basis.orthonormal else np.linalg.solve(gram(basis, count), moments)


# The closed forms of the specs, each in its own conventions.
_LN = log(3 + 2 * sqrt(2))
_A = (44 - 9 * sqrt(2) * _LN) / 32
_B = (39 * sqrt(10) * _LN - 20 * sqrt(5)) / 256
_P = sqrt(pi)
# normal-mapping-prt 7.2: SH (Condon-Shortley phase) to the coefficients of the unnormalised n . h_i.
SLOAN_HL2 = np.array([
    [sqrt(3) / (4 * _P), sqrt(6) / (4 * _P), 1 / (2 * _P), sqrt(2) / (4 * _P), 0, 3 * sqrt(30) / (32 * _P), sqrt(15) / (16 * _P), 3 * sqrt(10) / (32 * _P), 0],
    [sqrt(3) / (4 * _P), -sqrt(6) / (4 * _P), 1 / (2 * _P), sqrt(2) / (4 * _P), 0, -3 * sqrt(30) / (32 * _P), sqrt(15) / (16 * _P), 3 * sqrt(10) / (32 * _P), 0],
    [sqrt(3) / (4 * _P), 0, 1 / (2 * _P), -sqrt(2) / (2 * _P), 0, 0, sqrt(15) / (16 * _P), -3 * sqrt(10) / (16 * _P), 0]])
# normal-mapping-prt 7.1: SH to the first four shifted associated Legendre polynomials (HSH); both with
# the Condon-Shortley phase, which cancels in every entry.
SLOAN_HSH4 = np.array([
    [sqrt(2) / 2, 0, sqrt(6) / 4, 0, 0, 0, 0, 0, 0],
    [0, _A, 0, 0, 0, _B, 0, 0, 0],
    [0, 0, sqrt(2) / 4, 0, 0, 0, sqrt(30) / 8, 0, 0],
    [0, 0, 0, _A, 0, 0, 0, _B, 0]])
# irradiance-normal-mapping listing 2.1: SH (no Condon-Shortley phase) to the modified H-basis.
LISTING_MODH = np.array([
    [0.70711, 0, 1.2247, 0, 0, 0, 1.1859, 0, 0],
    [0, 0.70711, 0, 0, 0, 0.59293, 0, 0, 0],
    [0, 0, -0.70711, 0, 0, 0, -1.3693, 0, 0],
    [0, 0, 0, 0.70711, 0, 0, 0, 0.59293, 0],
    [0, 0, 0, 0, 0.70711, 0, 0, 0, 0],
    [0, 0, 0, 0, 0, 0, 0, 0, 0.70711]])
CONDON_SHORTLEY = np.array([1, -1, 1, -1, 1, -1, 1, -1, 1], dtype=np.float64)  # (-1)^m of the nine SH


def closed_form_checks() -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per closed form: (the spec's matrix, the same computed by integration in its conventions)."""
    hl2 = from_sh9_matrix(get_basis("hl2"), 3) * sqrt(3 / (2 * pi)) * CONDON_SHORTLEY  # unnormalised, CS phase
    return {"SH -> Half-Life 2 (normal-mapping-prt 7.2)": (SLOAN_HL2, hl2),
            "SH -> HSH, 4 (normal-mapping-prt 7.1)": (SLOAN_HSH4, from_sh9_matrix(get_basis("hsh"), 4)),
            "SH -> modified H-basis (irradiance-normal-mapping listing 2.1)": (LISTING_MODH, from_sh9_matrix(get_basis("modh"), 6))}
