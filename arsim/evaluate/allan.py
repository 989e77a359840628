"""Allan deviation of rate signals, and the fit of its white-noise and random-walk terms."""

from __future__ import annotations

import numpy as np


def allan_deviation(rates: np.ndarray, rate_hz: float, taus: np.ndarray) -> np.ndarray:
    """Overlapping Allan deviation of a rate signal (K,) or (K, A) at averaging times taus (s)."""
    x = np.asarray(rates, dtype=np.float64)
    x = x[:, None] if x.ndim == 1 else x
    dt = 1.0 / rate_hz
    theta = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0) * dt])
    out = []
    for tau in taus:
        m = int(round(tau * rate_hz))
        d = theta[2 * m:] - 2 * theta[m:-m] + theta[:-2 * m]
        out.append(np.sqrt(np.mean(d * d, axis=0) / (2 * (m * dt) ** 2)))
    return np.array(out).squeeze()


def fit_white_and_random_walk(taus: np.ndarray, adev: np.ndarray) -> tuple[float, float]:
    """Least-squares fit of sigma^2(tau) = N^2 / tau + K^2 tau / 3: returns (N, K), the white-noise
    density (per sqrt(Hz)) and the random-walk density (per sqrt(s))."""
    a = np.stack([1.0 / taus, taus / 3.0], axis=1) / adev[:, None] ** 2  # relative weights
    n2, k2 = np.linalg.lstsq(a, np.ones_like(taus), rcond=None)[0]
    return float(np.sqrt(max(n2, 0.0))), float(np.sqrt(max(k2, 0.0)))
