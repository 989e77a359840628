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


def _cone_cosine(camera: CameraIntrinsics) -> float:
    """Cosine of the widest angle between the optical axis and a ray through the image's border."""
    w, h = camera.width, camera.height
    u = np.r_[np.linspace(-0.5, w - 0.5, w + 1), np.full(h + 1, -0.5), np.linspace(-0.5, w - 0.5, w + 1),
              np.full(h + 1, w - 0.5)]
    v = np.r_[np.full(w + 1, -0.5), np.linspace(-0.5, h - 0.5, h + 1), np.full(w + 1, h - 0.5),
              np.linspace(-0.5, h - 0.5, h + 1)]
    return float(camera.unproject(np.stack([u, v], axis=-1))[:, 2].min())


def seen_by_views(camera_to_world: Rotation, camera: CameraIntrinsics, directions: np.ndarray,
                  chunk: int = 64) -> np.ndarray:
    """For each direction (K, 3), whether any of the camera orientations has it in its image. A cone
    around each view's axis picks the candidates (one matrix product); only they are projected."""
    seen = np.zeros(len(directions), dtype=bool)
    world_to_camera = camera_to_world.inv().as_matrix().reshape(-1, 3, 3)
    margin = _cone_cosine(camera) - 1e-6
    for start in range(0, len(world_to_camera), chunk):
        rotations = world_to_camera[start:start + chunk]
        near_axis = rotations[:, 2, :] @ directions.T > margin  # (c, K): row 2 is the optical axis in world
        view, k = np.nonzero(near_axis & ~seen)
        if k.size == 0:
            continue
        cam = np.einsum("nij,nj->ni", rotations[view], directions[k])
        px = camera.project(cam)
        inside = (px[:, 0] >= -0.5) & (px[:, 0] <= camera.width - 0.5) & (px[:, 1] >= -0.5) \
            & (px[:, 1] <= camera.height - 0.5)
        seen[k[inside]] = True
    return seen


def seen_directions(trajectory: Trajectory, camera: CameraIntrinsics, fps: float, directions: np.ndarray) -> np.ndarray:
    """For each direction (K, 3), whether any frame of the trajectory (at fps) has it in its image."""
    return seen_by_views(trajectory.camera_orientation(np.arange(0.0, trajectory.duration, 1.0 / fps)), camera, directions)


def sphere_coverage(trajectory: Trajectory, camera: CameraIntrinsics, fps: float, samples: int = 20000) -> float:
    """Fraction of the sphere's solid angle seen by at least one frame."""
    return float(seen_directions(trajectory, camera, fps, fibonacci_directions(samples)).mean())
