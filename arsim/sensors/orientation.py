"""Orientation from gyroscope readings (the dead-reckoning core every fusion filter starts from)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def _q_dot(q: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """dq/dt = q * (omega, 0) / 2 for a device-to-world quaternion (x, y, z, w) and body rate omega."""
    x, y, z, w = q
    ox, oy, oz = omega
    return 0.5 * np.array([
        w * ox + y * oz - z * oy,
        w * oy + z * ox - x * oz,
        w * oz + x * oy - y * ox,
        -x * ox - y * oy - z * oz,
    ])


def integrate_gyroscope(t_s: np.ndarray, omega: np.ndarray, start: Rotation) -> Rotation:
    """Device-to-world orientations at every other sample (t_0, t_2, t_4, ...), integrating body rates
    omega (K, 3) with the classical Runge-Kutta scheme over pairs of samples (the middle sample is the
    midpoint), fourth order for evenly spaced samples. Returns the orientations at t_s[0::2]."""
    q = start.as_quat()
    out = [q]
    for k in range(0, len(t_s) - 2, 2):
        h = t_s[k + 2] - t_s[k]
        k1 = _q_dot(q, omega[k])
        k2 = _q_dot(q + 0.5 * h * k1, omega[k + 1])
        k3 = _q_dot(q + 0.5 * h * k2, omega[k + 1])
        k4 = _q_dot(q + h * k3, omega[k + 2])
        q = q + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        q /= np.linalg.norm(q)
        out.append(q)
    return Rotation.from_quat(np.array(out))
