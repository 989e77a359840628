"""The lighting-estimation literature's metrics (README: Light estimation): renders lit by an estimate
against the same lit by the truth, over a mask; main lights; SH coefficients.

- si_rmse: the RMSE after the estimate is scaled by the one factor that fits it best to the truth
  (least squares), over the truth's RMS: the light's shape, whatever its brightness;
- rmse: the plain RMSE over the truth's RMS (normalised RMSE);
- angular_error_deg: the mean angle between the estimate's and the truth's RGB vectors per pixel: the
  light's colour, whatever its brightness;
- direction_error_deg, intensity_ratio: a main light's direction and its luminance against the truth's;
- sh_relative_error: the 27 coefficients' difference over the truth's norm.
"""

from __future__ import annotations

import numpy as np

from arsim.sensors.camera import LUMA  # Rec. 709, linear


def _pixels(image: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    image = np.asarray(image, dtype=np.float64)[..., :3]
    return image.reshape(-1, 3) if mask is None else image[np.asarray(mask, dtype=bool)]


def rmse(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    e, t = _pixels(estimate, mask), _pixels(truth, mask)
    return float(np.sqrt(np.mean((e - t) ** 2) / max(np.mean(t ** 2), 1e-300)))


def si_rmse(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    e, t = _pixels(estimate, mask), _pixels(truth, mask)
    scale = float((e * t).sum() / max((e * e).sum(), 1e-300))
    return float(np.sqrt(np.mean((scale * e - t) ** 2) / max(np.mean(t ** 2), 1e-300)))


def angular_error_deg(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    e, t = _pixels(estimate, mask), _pixels(truth, mask)
    # (atan2 of the cross and dot products: exact for equal directions, where arccos of their cosine is not)
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(e, t), axis=1), (e * t).sum(axis=1))).mean())


def direction_error_deg(estimate: np.ndarray, truth: np.ndarray) -> float:
    a, b = np.asarray(estimate, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), a @ b)))


def intensity_ratio(estimate: np.ndarray, truth: np.ndarray) -> float:
    return float(np.asarray(estimate, dtype=np.float64) @ LUMA / max(float(np.asarray(truth, dtype=np.float64) @ LUMA), 1e-300))


def sh_relative_error(estimate: np.ndarray, truth: np.ndarray) -> float:
    e, t = np.asarray(estimate, dtype=np.float64), np.asarray(truth, dtype=np.float64)
    return float(np.linalg.norm(e - t) / max(np.linalg.norm(t), 1e-300))
