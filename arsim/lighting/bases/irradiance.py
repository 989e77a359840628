"""Directional irradiance in tangent space, E(n) = int L(w) V(w) max(0, n . w) dw over the upper
hemisphere (the surface hides the lower one), from radiance samples and from distant point lights."""

from __future__ import annotations

import numpy as np

CHUNK = 4096  # normals per block of the sums (keeps the (normals x samples) products small)
COSINE_KERNEL = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)  # a_l of bands 0-2 (Ramamoorthi, Hanrahan)


def irradiance(normals: np.ndarray, directions: np.ndarray, radiance_weighted: np.ndarray,
               lights: np.ndarray | None = None, light_power: np.ndarray | None = None) -> np.ndarray:
    """E at unit normals (..., 3) from samples (K, 3) with radiance x solid angle (K, C) (samples below
    the horizon, z < 0, add nothing), and optional point lights (J, 3) of irradiance (J, C) at normal
    incidence. Returns (..., C)."""
    normals = np.asarray(normals, dtype=np.float64)
    flat = normals.reshape(-1, 3)
    above = directions[:, 2] > 0
    d, lw = directions[above], np.asarray(radiance_weighted, dtype=np.float64)[above]
    out = np.empty((len(flat), lw.shape[1]))
    for start in range(0, len(flat), CHUNK):
        n = flat[start:start + CHUNK]
        out[start:start + CHUNK] = np.maximum(n @ d.T, 0.0) @ lw
        if lights is not None and len(lights):
            lit = np.asarray(lights, dtype=np.float64)
            visible = lit[:, 2] > 0
            out[start:start + CHUNK] += np.maximum(n @ lit[visible].T, 0.0) @ np.asarray(light_power, dtype=np.float64)[visible]
    return out.reshape(normals.shape[:-1] + (lw.shape[1],))


def sh9_irradiance_coefficients(directions: np.ndarray, radiance_weighted: np.ndarray,
                                lights: np.ndarray | None = None, light_power: np.ndarray | None = None) -> np.ndarray:
    """(9, C): the SH of the radiance over the whole sphere (zero below the horizon) convolved with the
    clamped cosine (a_l = pi, 2 pi / 3, pi / 4; Ramamoorthi and Hanrahan): E's SH as the spec's bake
    (2.2.1) computes it before converting to another basis."""
    from arsim.lighting.bases.functions import sh9

    above = directions[:, 2] > 0
    coeffs = sh9(directions[above]).T @ np.asarray(radiance_weighted, dtype=np.float64)[above]
    if lights is not None and len(lights):
        visible = np.asarray(lights)[:, 2] > 0
        coeffs += sh9(np.asarray(lights)[visible]).T @ np.asarray(light_power, dtype=np.float64)[visible]
    return coeffs * COSINE_KERNEL[:, None]
