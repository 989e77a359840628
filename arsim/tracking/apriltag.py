"""The tag's pose per frame: its corners from a detector by name (tracking/detectors.py: AprilTag 3 or
OpenCV's), then the camera pose from the four corners with solvePnP's IPPE_SQUARE, the solver made for a
square of known size, refined by Levenberg-Marquardt where that helps.

Frames are linearised with the camera's inverse response first (when it is known: the capture
recovers it): the response brightens the blurred edge of the black square, which then looks smaller,
and the tag farther away. On the default AR path the 95th percentile of the position error was 2.0 %
of the distance on the 8-bit codes and 0.5 % linearised (OpenCV's detector).

The tag lies on the table (README: Conventions): centred at the world origin, its x axis along world +x,
its image top towards world -z, its normal +y. IPPE_SQUARE wants the corners in the marker's own frame
(x right, y up the tag image, z out of it), which is the world turned by MARKER_TO_WORLD.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from arsim.core.conventions import CameraIntrinsics
from arsim.core.tags import DEFAULT_DETECTOR
from arsim.tracking.detectors import make_detector

# Levenberg-Marquardt after IPPE, per detector: where it lowers the pose error on the default AR path
# (benchmarks/bench_tracking.py).
REFINE_POSE = {"apriltag3": True, "opencv": False}
# Columns: the marker's x, y (up the tag image) and z (its normal) in world axes.
MARKER_TO_WORLD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class TagPose:
    """What the tracker saw in one frame: the world-to-camera transform (OpenCV camera axes), or
    nothing when the tag was not found (the frame is lost and no virtual object is drawn)."""

    rotation: np.ndarray | None  # (3, 3) world to camera
    translation: np.ndarray | None  # (3,) world origin (the tag's centre) in camera coordinates, metres
    corners: np.ndarray | None  # (4, 2) sub-pixel image corners in the official order (core/tags.py)
    # With the IMU fused (tracking/fusion.py): no tag pose was taken in this frame, the pose is the filter's
    # extrapolation, since_tag_s after the last one; the filter's 1-sigma rotation (deg) and position (m).
    extrapolated: bool = False
    since_tag_s: float = 0.0
    sigma_rotation_deg: float | None = None
    sigma_position_m: float | None = None

    @property
    def found(self) -> bool:
        return self.rotation is not None

    @property
    def view_matrix(self) -> np.ndarray:
        """4 x 4 world-to-camera matrix (OpenCV axes: x right, y down, z forward)."""
        view = np.eye(4)
        view[:3, :3], view[:3, 3] = self.rotation, self.translation
        return view

    @property
    def camera_position(self) -> np.ndarray:
        """The camera's centre in world coordinates: -R^T t, summed term by term (a BLAS product of this
        size rounds by the arrays' alignment in memory: runs of the same seed differed in the last bit)."""
        r, t = self.rotation, self.translation
        return -(r[0] * t[0] + r[1] * t[1] + r[2] * t[2])


LOST = TagPose(None, None, None)

BRIGHT_GAIN_MAX = 64.0  # the most a dark frame's linear codes are raised (beyond it, noise would be)


class TagTracker:
    """Finds one tag (family, id, side of its black square) in 8-bit frames with a detector by name
    (tracking/detectors.py) and returns its pose: IPPE for a square, then, where the detector's corners
    gain from it, Levenberg-Marquardt on the four corners (REFINE_POSE)."""

    def __init__(self, camera: CameraIntrinsics, tag_size_m: float, tag_id: int = 0, family: str = "tag36h11",
                 linear_of_code: np.ndarray | None = None, detector: str = DEFAULT_DETECTOR):
        """linear_of_code (256,): the camera's inverse response (relative exposure of each 8-bit code),
        used to linearise frames before detection; None: detect on the codes."""
        self.detector_name = detector
        self.detector = make_detector(detector, family, tag_id)
        self.linear = None if linear_of_code is None else np.asarray(linear_of_code, dtype=np.float64)
        self.linearise = None if self.linear is None else self._codes(self.linear[-1])
        self.camera, self.tag_id = camera, tag_id
        h = tag_size_m / 2
        # IPPE_SQUARE's order: top-left, top-right, bottom-right, bottom-left, in the marker frame.
        self.marker_corners = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])

    def _corners(self, grey: np.ndarray) -> np.ndarray | None:
        return self.detector.corners(grey)

    def raised_table(self, grey: np.ndarray) -> np.ndarray | None:
        """For a dark frame, (256,) uint8: each code's linear exposure raised by the constant gain that
        brings the frame's 99th percentile up to three quarters of the scale (at most BRIGHT_GAIN_MAX times);
        None for a frame that is not dark. The auto-exposure's first frames leave the tag's white at 20 of 255 in
        linear codes, too little contrast for the detector."""
        histogram = cv2.calcHist([grey], [0], None, [256], [0, 256]).ravel()
        bright = int(np.searchsorted(np.cumsum(histogram), 0.99 * grey.size))  # the 99th percentile's code
        full = self.linear[-1]
        level = max(self.linear[bright] / 0.75, full / BRIGHT_GAIN_MAX)
        return None if level >= full else self._codes(level)

    def _codes(self, level: float) -> np.ndarray:
        """(256,) uint8: each code's linear exposure in 8 bits, `level` at 255."""
        return np.clip(np.round(255 * self.linear / level), 0, 255).astype(np.uint8)

    def track(self, frame: np.ndarray, index: int | None = None) -> TagPose:
        """The tag's pose in an 8-bit RGB, RGBA or grey frame, or LOST (index: the frame's, for trackers that need
        it: FusedTracker)."""
        grey = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY) if frame.ndim == 3 else frame
        if self.linearise is None:
            image_corners = self._corners(grey)
        else:
            image_corners = self._corners(cv2.LUT(grey, self.linearise))
            # Not found in a dark frame: again, raised. Only then: the detector's thresholds are in codes, so a
            # gain changes the corners it refines a little (0.6 % -> 0.8 % of the distance, p95, on the
            # default AR path, had every dark frame been raised).
            raised = self.raised_table(grey) if image_corners is None else None
            if raised is not None:
                image_corners = self._corners(cv2.LUT(grey, raised))
        if image_corners is None:
            return LOST
        ok, rvec, tvec = cv2.solvePnP(self.marker_corners, image_corners, self.camera.matrix, self.camera.distortion,
                                      flags=cv2.SOLVEPNP_IPPE_SQUARE)
        if not ok:
            return LOST
        if REFINE_POSE[self.detector_name]:
            rvec, tvec = cv2.solvePnPRefineLM(self.marker_corners, image_corners, self.camera.matrix,
                                              self.camera.distortion, rvec, tvec)
        marker_to_camera = cv2.Rodrigues(rvec)[0]
        return TagPose(marker_to_camera @ MARKER_TO_WORLD.T, tvec.ravel(), image_corners)
