"""The Phong lobe in spherical harmonics: the zonal coefficients Lambda_l rho_l of thesis eq. 2.33."""

from __future__ import annotations

import numpy as np


def phong_zonal_coefficients(exponent: float, order: int) -> np.ndarray:
    """Lambda_l rho_l for l = 0 .. order-1 (eq. 2.33, Alg. 4.6) of the normalised lobe max(0, cos)^s.

    Alg. 4.6 multiplies numerator and denominator separately, which overflows to inf/inf = NaN near
    l = 170; here the product is taken as a product of ratios, each at most 1 in magnitude for large l,
    so it stays finite at any order. kappa_0 = 1: the map of a constant environment is that constant.
    """
    s = float(exponent)
    kappa = np.ones(order)
    odd = even = 1.0
    for l in range(1, order):
        if l % 2:
            odd *= (s - l + 2) / (s + l + 1)
            kappa[l] = odd
        else:
            even *= (s - l + 2) / (s + l + 1)
            kappa[l] = even
    return kappa
