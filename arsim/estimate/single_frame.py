"""The single-frame baseline (README: Light estimation): what one camera image tells of the light, with
nothing remembered from earlier frames, as ARCore's ambient mode works. The frame's pixels on a grid,
linearised (the recovered response, over the frame's exposure; clipped and black codes left out), turned
into world directions by the phone's own orientation (the IMU's fused one):
- ambient intensity and colour correction: the pixels' mean;
- SH of the radiance: the least-squares fit to the pixels' radiance at their directions, pulled towards a
  uniform light of their mean (PRIOR) where the frame does not see (most of the sphere);
- main light: the brightest seen pixels' energy-weighted direction and their first moment along it;
- cubemap: the seen pixels' mean per texel, the SH elsewhere.
"""

from __future__ import annotations

import numpy as np

from arsim.core.conventions import CameraIntrinsics
from arsim.estimate.shapes import (CUBE_SIZE, LUMA, MAIN_LIGHT_SHARE, LightEstimate, cube_means, main_light_intensity,
                                   sh_cubemap)
from arsim.lighting.bases.functions import sh9

GRID = 8  # every GRID-th pixel of every GRID-th row
PRIOR = 0.05  # the pull towards a uniform light, relative to the fit's own weight per coefficient


class SingleFrameEstimator:
    def __init__(self, camera: CameraIntrinsics):
        rows, cols = np.mgrid[GRID // 2:camera.height:GRID, GRID // 2:camera.width:GRID]
        self.rows, self.cols = rows.ravel(), cols.ravel()
        self.bearings = camera.unproject(np.stack([self.cols, self.rows], axis=-1).astype(np.float64))
        # each grid pixel's solid angle: the pixel's over the cosine-cubed of its angle from the axis, x GRID^2
        self.omega = GRID * GRID * self.bearings[:, 2] ** 3 / (camera.fx * camera.fy)

    def estimate(self, codes: np.ndarray, radiance_of_code: np.ndarray, camera_to_world: np.ndarray) -> LightEstimate:
        """One frame's estimate: codes (H, W, 3) uint8, radiance_of_code (256, 3) (the inverse response over
        the frame's exposure), the camera's world orientation (3, 3)."""
        c = codes[self.rows, self.cols]
        seen = ((c < 250) & (c > 3)).all(axis=1)
        radiance = np.take_along_axis(np.asarray(radiance_of_code, dtype=np.float64), c.astype(np.int64), axis=0)[seen]
        d = self.bearings[seen] @ np.asarray(camera_to_world, dtype=np.float64).T
        omega = self.omega[seen]
        if not len(radiance):  # (a frame all clipped or black: a grey light)
            radiance, d, omega = np.ones((1, 3)), np.array([[0.0, 1.0, 0.0]]), np.ones(1)
        mean = (radiance * omega[:, None]).sum(axis=0) / omega.sum()
        ambient = float(mean @ LUMA)
        y = sh9(d)
        gram = (y * omega[:, None]).T @ y
        prior = np.zeros((9, 3))
        prior[0] = mean * np.sqrt(4 * np.pi)  # a uniform light of the mean radiance
        weight = PRIOR * np.trace(gram) / 9
        sh = np.linalg.solve(gram + weight * np.eye(9), (y * omega[:, None]).T @ radiance + weight * prior)
        luminance = radiance @ LUMA
        bright = luminance >= MAIN_LIGHT_SHARE * luminance.max()
        w = (luminance * omega)[bright]
        direction = (d[bright] * w[:, None]).sum(axis=0)
        direction /= max(np.linalg.norm(direction), 1e-300)
        intensity = main_light_intensity(radiance[bright], omega[bright], d[bright], direction)
        means, weights = cube_means(d, radiance, omega, CUBE_SIZE)
        faces = np.where(weights[..., None] > 0, means, sh_cubemap(sh))
        green = mean[1] if mean[1] > 0 else 1.0
        return LightEstimate(sh, direction, intensity, faces.astype(np.float32), ambient,
                             np.array([mean[0] / green, 1.0, mean[2] / green, ambient]))
