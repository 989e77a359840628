"""Direct (photometric) alignment of two keyframes, for the views that features cannot pin: a bare ceiling
with one lamp, a dark wall at the sensor's noise. Every pixel's intensity is compared instead of a few
corners', as direct image alignment does (Lucas-Kanade over a rotation, with an affine gain and offset
between the two exposures, as OpenCV's ECC is invariant to): the rotation minimising the robust sum of
squared differences of the two blurred, undistorted images, by SciPy's `least_squares` with the
analytic Jacobian, coarse (more blur: a wider basin) then fine. Its covariance is the Gauss-Newton
one, s² (JᵀJ)⁻¹ over the rotation with the photometric terms marginalised, scaled by how many pixels
the blur makes one independent sample.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from arsim.capture.align import scaled_camera
from arsim.core.conventions import CameraIntrinsics

DIRECT_SCALE = 0.5  # of the keyframe's features size (a quarter of the frame: 160 x 120 at 640 x 480)
BLUR_PX = (3.0, 1.2)  # the Gaussian blur of each level, coarse then fine (px at DIRECT_SCALE)
CODE_RANGE = (6, 249)  # codes outside carry no texture of the scene (black, clipped)
STRIDE = 2  # every second pixel of each row and column is compared (the blur makes neighbours redundant)
MARGIN_PX = 4  # pixels this close to the other image's border or mask are not compared
MIN_OVERLAP = 0.25  # of the pixels: less overlap is too little to align
MIN_CORRELATION = 0.9  # the aligned images' correlation coefficient below which the match is not trusted
LOSS_SIGMAS = 3.0  # the soft-L1 loss's scale in the residuals' robust standard deviations


@dataclass(frozen=True)
class DirectImage:
    grey: np.ndarray  # (H, W) float32: the log of the relative radiance, undistorted to `camera`, unblurred
    valid: np.ndarray  # (H, W) bool: every channel's code within CODE_RANGE


class DirectImages:
    """Keyframe images for direct alignment: undistorted to a pinhole camera at DIRECT_SCALE of the
    features' camera, linearised through the response and divided by the lens's fall-off (which does not
    turn with the view: left in, it pulls a bare view's alignment towards no rotation, 0.5 degrees on the
    ceiling), in log (the exposures' ratio an offset; a lamp does not outweigh the wall), with the pixels
    that carry texture marked."""

    def __init__(self, camera: CameraIntrinsics, frame_camera: CameraIntrinsics, linear: np.ndarray,
                 falloff: np.ndarray):
        """camera: the features' (the images given are at its size); frame_camera, falloff (H, W): the
        full frame's; linear (256, 3): the response."""
        self.camera = replace(scaled_camera(camera, DIRECT_SCALE), k1=0.0, k2=0.0)
        w, h = self.camera.width, self.camera.height
        # where each pinhole pixel lies in the features' image (distortion applied): one remap undistorts and
        # scales down (the source blurred first against aliasing)
        grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), axis=-1).astype(np.float64)
        self.rays = self.camera.unproject(grid)  # (H, W, 3) unit bearings of the pinhole pixels
        source = camera.project(self.rays)
        self.map_x, self.map_y = source[..., 0].astype(np.float32), source[..., 1].astype(np.float32)
        full = frame_camera.project(self.rays).astype(np.float32)
        self.log_falloff = np.log(cv2.remap(falloff.astype(np.float32), full[..., 0], full[..., 1], cv2.INTER_LINEAR,
                                            borderMode=cv2.BORDER_REPLICATE))
        self.log_linear = np.log(np.maximum(linear, 1e-6)).astype(np.float32)

    def __call__(self, codes: np.ndarray) -> DirectImage:
        """codes: (h, w, 3) uint8 at the features' size."""
        lo, hi = CODE_RANGE
        textured = np.all((codes >= lo) & (codes <= hi), axis=2).astype(np.float32)
        linear = np.exp(np.mean([self.log_linear[codes[..., c], c] for c in range(3)], axis=0))
        blur = 0.5 / DIRECT_SCALE
        warp = (self.map_x, self.map_y, cv2.INTER_LINEAR)
        radiance = cv2.remap(cv2.GaussianBlur(linear.astype(np.float32), (0, 0), blur), *warp,
                             borderMode=cv2.BORDER_REPLICATE)
        # pixels near black are noise more than scene, and clipped ones are not the radiance: a pixel counts
        # where every pixel its blur takes in is within the range (measured on the dim studio's noise-bound
        # views: with a limit on the blurred codes instead, pairs' p90 error 0.14 -> 0.36 degrees)
        mask = cv2.remap(cv2.GaussianBlur(textured, (0, 0), blur), *warp, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0.0)
        grey = np.log(np.maximum(radiance, 1e-6)) - self.log_falloff
        return DirectImage(grey.astype(np.float32), mask > 0.99)


def _level(image: DirectImage, blur: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The image blurred, its x and y gradients, and its mask shrunk by the blur and the margin."""
    grey = cv2.GaussianBlur(image.grey, (0, 0), blur)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3, scale=1 / 8)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3, scale=1 / 8)
    size = 2 * int(np.ceil(blur + MARGIN_PX)) + 1
    mask = cv2.erode(image.valid.astype(np.uint8), np.ones((size, size), np.uint8), borderValue=0) > 0
    return grey, gx, gy, mask


@dataclass(frozen=True)
class DirectMatch:
    rotation: Rotation  # Q with bearings_a ≈ Q bearings_b (Q = R_a⁻¹ R_b)
    covariance: np.ndarray  # (3, 3) rad², b's axes (Q = Q̂ exp(r))
    correlation: float  # of the aligned images
    overlap: float  # the fraction of b's pixels compared


def align_direct(a: DirectImage, b: DirectImage, images: DirectImages, expected: Rotation) -> DirectMatch | None:
    """b aligned to a, started from the expected Q; None where the views overlap too little, the alignment
    fails, or the aligned images do not correlate."""
    cam = images.camera
    h, w = a.grey.shape
    q = expected
    fit = None
    for blur in BLUR_PX:
        ga, gxa, gya, ma = _level(a, blur)
        gb, _, _, mb = _level(b, blur)
        # b's pixels compared: textured, and landing inside a's textured region at the start (the set stays
        # fixed through the level, so that the cost is one function)
        mb[1::STRIDE] = False
        mb[:, 1::STRIDE] = False
        rays = images.rays[mb]
        values = gb[mb].astype(np.float64)
        start = q.apply(rays)
        front = start[:, 2] > 1e-3
        px = cam.project(np.where(front[:, None], start, 1.0))
        inside = front & (px[:, 0] >= 0) & (px[:, 0] <= w - 1) & (px[:, 1] >= 0) & (px[:, 1] <= h - 1)
        inside[inside] = ma[np.round(px[inside, 1]).astype(int), np.round(px[inside, 0]).astype(int)]
        overlap = inside.sum() * STRIDE**2 / (h * w)
        if overlap < MIN_OVERLAP or inside.sum() < 50:
            return None
        rays, values = rays[inside], values[inside]
        base = q
        # a's image and its gradients in one three-channel image: one remap per step gives all three (the same
        # values as three remaps), kept for the Jacobian, which SciPy asks for at the x it has just evaluated
        stack = cv2.merge([ga, gxa, gya])
        constant = (-values, -np.ones_like(values))  # the Jacobian's gain and offset columns
        last = {}

        def sample(x):
            """b's rays turned by x, and a's image and gradients where they land (the last x's kept)"""
            key = x.tobytes()
            if last.get("key") != key:
                turn = base * Rotation.from_rotvec(x[:3])
                d = turn.apply(rays)
                u = (cam.fx * d[:, 0] / d[:, 2] + cam.cx).astype(np.float32)[:, None]
                v = (cam.fy * d[:, 1] / d[:, 2] + cam.cy).astype(np.float32)[:, None]
                warped = cv2.remap(stack, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)[:, 0]
                last.update(key=key, turn=turn, d=d, warped=warped)
            return last["turn"], last["d"], last["warped"]

        def residuals(x):
            return sample(x)[2][:, 0] - (x[3] * values + x[4])

        def jacobian(x):
            turn, d, warped = sample(x)
            gx, gy = warped[:, 1], warped[:, 2]
            z = d[:, 2]
            # d(pixel)/d(ray) for the pinhole, times d(ray)/d(x) = -Q [b]x (the right perturbation):
            # g (-Q [b]x) = b x (g Q)
            # (written out per column: the same products and sums as through stacked (n, 3) arrays and np.cross)
            grad = np.empty((len(z), 3))  # d(intensity)/d(ray)
            grad[:, 0] = gx * (cam.fx / z) + gy * 0.0
            grad[:, 1] = gx * 0.0 + gy * (cam.fy / z)
            grad[:, 2] = gx * (-cam.fx * d[:, 0] / z**2) + gy * (-cam.fy * d[:, 1] / z**2)
            g = grad @ turn.as_matrix()
            return np.column_stack([rays[:, 1] * g[:, 2] - rays[:, 2] * g[:, 1], rays[:, 2] * g[:, 0] - rays[:, 0] * g[:, 2],
                                    rays[:, 0] * g[:, 1] - rays[:, 1] * g[:, 0], *constant])

        r0 = residuals(np.array([0, 0, 0, 1.0, 0.0]))
        spread = 1.4826 * np.median(np.abs(r0 - np.median(r0))) + 1e-4  # a robust scale to start
        fit = least_squares(residuals, np.array([0, 0, 0, 1.0, 0.0]), jac=jacobian, loss="soft_l1",
                            f_scale=LOSS_SIGMAS * spread, method="trf", x_scale="jac", max_nfev=40)
        if not fit.success:
            return None
        q = base * Rotation.from_rotvec(fit.x[:3])
    r = fit.fun
    centred = values - values.mean()
    warped = r + fit.x[3] * values + fit.x[4]
    correlation = float(np.dot(centred, warped - warped.mean())
                        / (np.linalg.norm(centred) * np.linalg.norm(warped - warped.mean()) + 1e-12))
    if correlation < MIN_CORRELATION:
        return None
    # Gauss-Newton covariance of the rotation, the gain and offset marginalised (Schur complement); the
    # residuals of neighbouring pixels are correlated over the blur's footprint, so each counts as a fraction
    sigma = 1.4826 * np.median(np.abs(r - np.median(r)))
    jtj = fit.jac.T @ fit.jac
    info = jtj[:3, :3] - jtj[:3, 3:] @ np.linalg.solve(jtj[3:, 3:], jtj[3:, :3])
    footprint = max(1.0, 4 * np.pi * BLUR_PX[-1] ** 2 / STRIDE**2)
    # (an axis the images do not pin, a uniform wall's, gets a variance of a radian squared: no weight)
    values_info, axes = np.linalg.eigh(info)
    variances = np.minimum(sigma**2 * footprint / np.maximum(values_info, 1e-12), 1.0)
    covariance = (axes * variances) @ axes.T
    return DirectMatch(q, covariance, correlation, float(overlap))


def align_direct_all(images: DirectImages, jobs: list[tuple[DirectImage, DirectImage, Rotation]]) -> list[DirectMatch | None]:
    """align_direct of each (a, b, expected) in jobs, in order: a share of a refinement's alignments, as one
    call to a worker process (the images of the share travel once, those shared by pairs once)."""
    return [align_direct(a, b, images, expected) for a, b, expected in jobs]
