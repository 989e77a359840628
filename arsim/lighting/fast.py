"""`fast`: exact maps in about a second, through spherical harmonics of sufficient order.

The maps are convolutions of the sphere with the rotationally symmetric Phong lobe, so in SH they are
the probe's coefficients times the lobe's zonal coefficients (eq. 2.31/2.33). The coefficients are the
exact sums over the angle map's texels with their solid angles (as `accurate` sums), so the only
approximations are the truncation of the lobe's series and the interpolation of the synthesised map
(and, like `accurate`, it divides by the lobe sum of the texel weights, carried as a fourth channel):
each exponent gets the order at which its zonal coefficients have fallen below TRUNCATION (about
4.2 sqrt(s) bands; at least MIN_ORDER, because the clamped cosine of s = 1 decays only like l^-2.5).

Measured against `accurate` at 512² by benchmarks/maps_accuracy.py: mean error below 0.1 % and max
error a few percent at most for every exponent up to 1280 on the bundled assets.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from arsim.lighting.sh import MAX_ORDER, probe_with_weights, sh_coefficients, sh_maps

TRUNCATION = 1e-6
MIN_ORDER = 64


def order_for_exponent(exponent: float) -> int:
    """Bands needed so that the Phong lobe's zonal coefficients beyond them are below TRUNCATION:
    kappa_l ~ exp(-l^2 / 2s) for large s."""
    order = int(np.ceil(np.sqrt(2.0 * exponent * np.log(1.0 / TRUNCATION)))) + 1
    return int(np.clip(order, MIN_ORDER, MAX_ORDER))


def fast_coefficients(env: np.ndarray, exponents: Sequence[float]) -> np.ndarray:
    """SH coefficients of radiance and weights (order^2, 4) at the largest order the exponents need."""
    return sh_coefficients(probe_with_weights(env), max(order_for_exponent(s) for s in exponents))


def fast_maps(env: np.ndarray, exponents: Sequence[float], coeffs: np.ndarray | None = None) -> np.ndarray:
    """Maps (E, N, N, 3) float32 for the exponents, each through SH of the order its lobe needs,
    normalised by the weights' own SH image as `accurate` normalises by its sum of weights."""
    coeffs = fast_coefficients(env, exponents) if coeffs is None else coeffs
    return sh_maps(env, exponents, [order_for_exponent(s) for s in exponents], coeffs=coeffs, normalise=True)
