"""How much of the sphere a camera trajectory sees (the capture sweep must see all of it)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.conventions import CameraIntrinsics
from arsim.sensors.trajectory import Trajectory


def fibonacci_directions(n: int) -> np.ndarray:
    """n unit directions spread evenly over the sphere (equal solid angle each)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + 5.0**0.5) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def seen_by_views(camera_to_world: Rotation, camera: CameraIntrinsics, directions: np.ndarray) -> np.ndarray:
    """For each direction (K, 3), whether any of the camera orientations has it in its image."""
    seen = np.zeros(len(directions), dtype=bool)
    for rotation in camera_to_world:
        cam = rotation.inv().apply(directions)
        ahead = cam[:, 2] > 1e-9
        px = camera.project(np.where(ahead[:, None], cam, 1.0))
        inside = ahead & (px[:, 0] >= -0.5) & (px[:, 0] <= camera.width - 0.5) \
            & (px[:, 1] >= -0.5) & (px[:, 1] <= camera.height - 0.5)
        seen |= inside
    return seen


def seen_directions(trajectory: Trajectory, camera: CameraIntrinsics, fps: float, directions: np.ndarray) -> np.ndarray:
    """For each direction (K, 3), whether any frame of the trajectory (at fps) has it in its image."""
    return seen_by_views(trajectory.camera_orientation(np.arange(0.0, trajectory.duration, 1.0 / fps)), camera, directions)


def sphere_coverage(trajectory: Trajectory, camera: CameraIntrinsics, fps: float, samples: int = 20000) -> float:
    """Fraction of the sphere's solid angle seen by at least one frame."""
    return float(seen_directions(trajectory, camera, fps, fibonacci_directions(samples)).mean())
