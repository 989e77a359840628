"""Quadrature over the upper hemisphere and the sphere, exact enough for the Gram matrices of every basis
to 1e-12: Gauss-Legendre in u with z = u^2 (the non-polynomial bases have sqrt(z) and sqrt(z / (1 + z)),
which are smooth in u), and the uniform rule in phi (exact for trigonometric polynomials)."""

from __future__ import annotations

import numpy as np


def hemisphere_quadrature(n_u: int = 48, n_phi: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) unit directions with z >= 0 and (K,) weights summing to 2 pi."""
    nodes, weights = np.polynomial.legendre.leggauss(n_u)
    u = 0.5 * (nodes + 1)
    z = u * u
    wz = 0.5 * weights * 2 * u  # dz = 2u du, u in [0, 1]
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    s = np.sqrt(1 - zz * zz)
    directions = np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    return directions, np.repeat(wz * 2 * np.pi / n_phi, n_phi)


def sphere_quadrature(n_z: int = 48, n_phi: int = 96) -> tuple[np.ndarray, np.ndarray]:
    """(K, 3) unit directions over the whole sphere and (K,) weights summing to 4 pi (Gauss-Legendre in z)."""
    nodes, weights = np.polynomial.legendre.leggauss(n_z)
    phi = (np.arange(n_phi) + 0.5) * 2 * np.pi / n_phi
    zz, pp = np.meshgrid(nodes, phi, indexing="ij")
    s = np.sqrt(1 - zz * zz)
    directions = np.stack([s * np.cos(pp), s * np.sin(pp), zz], axis=-1).reshape(-1, 3)
    return directions, np.repeat(weights * 2 * np.pi / n_phi, n_phi)
