"""Error metrics of the thesis (eq. 6.1/6.2), as README's Conventions pin them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MapError:
    mean_percent: float
    max_percent: float


def relative_error(reference: np.ndarray, value: np.ndarray) -> np.ndarray:
    """Per texel and channel |a - v| / (a + eps), eps = 1e-4 mean(a), over the given texels (..., 3)."""
    a = np.asarray(reference, dtype=np.float64)
    v = np.asarray(value, dtype=np.float64)
    eps = 1e-4 * a.mean()
    return np.abs(a - v) / (a + eps)


def map_error(reference: np.ndarray, value: np.ndarray) -> MapError:
    """relative_error's mean and maximum in percent. Pass only texels inside the disk."""
    rel = relative_error(reference, value)
    return MapError(float(100 * rel.mean()), float(100 * rel.max()))
