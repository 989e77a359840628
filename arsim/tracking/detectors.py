"""Tag detectors by name ([ar] detector), behind one small interface: corners(grey) gives the tag's four
corners in OpenCV's pixel convention (pixel centres at integer coordinates) and the official order
(top-left, top-right, bottom-right, bottom-left of the printed image: core/tags.py), or None.

- apriltag3: AprilTag 3, the reference implementation (pupil-apriltags). Its corners put pixel centres at
  half-integers: half a pixel is taken off. Its quad search runs on the frame decimated by 2; the corners
  are refined on the full frame (refine_edges).
- opencv: OpenCV's ArUco module, with AprilTag's corner refinement (the same half-pixel offset). OpenCV
  orders the corners as it draws the tag, which for the AprilTag families is turned from the official
  image (sensors.table.official_turn): they are turned back.
"""

from __future__ import annotations

import os

import cv2
import numpy as np

from arsim.core.tags import TAG_FAMILIES, apriltag_detector, check_detector
from arsim.sensors.table import official_turn

MIN_WHITE_BLACK_DIFF = 20  # 8-bit codes (linearised): see OpenCVDetector
# Each detector's corner noise (px, RMS about the truth's projection on rendered frames: tests/test_tracking.py
# measures 0.052 and 0.100): what the IMU fusion weighs its poses by.
CORNER_SIGMA_PX = {"apriltag3": 0.05, "opencv": 0.10}


class AprilTag3Detector:
    def __init__(self, family: str, tag_id: int, decimate: float = 2.0):
        self.tag_id = tag_id
        # its quads fitted and decoded on every core: the same corners as on one thread (the detections are
        # sorted by id before they are returned; one tag per id in a frame), a 640 x 480 frame in 30 % less
        # wall time on two cores
        self.detector = apriltag_detector(family, nthreads=os.cpu_count() or 1, quad_decimate=decimate,
                                          refine_edges=1)

    def corners(self, grey: np.ndarray) -> np.ndarray | None:
        for d in self.detector.detect(np.ascontiguousarray(grey)):
            if d.tag_id == self.tag_id:
                # AprilTag's corners wrap counter-clockwise from the official bottom-left: reversed, the fourth
                # (the top-left) first
                return d.corners[::-1].astype(np.float64) - 0.5
        return None


class OpenCVDetector:
    def __init__(self, family: str, tag_id: int):
        dictionary = cv2.aruco.getPredefinedDictionary(TAG_FAMILIES[family].opencv_dictionary)
        parameters = cv2.aruco.DetectorParameters()
        parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_APRILTAG
        # AprilTag's quad search leaves out the 4 x 4 tiles whose codes span less than this: flat, noisy
        # table and wall hold no edge of the tag, and clustering their noise was four fifths of the tracker's
        # time. The tag's edges span far more; on the default AR path the corners are the same to the bit
        # as with the default of 5, in a fifth of the time.
        parameters.aprilTagMinWhiteBlackDiff = MIN_WHITE_BLACK_DIFF
        # The AprilTag corner refinement runs AprilTag's own quad search over the image it is given:
        # 130 ms on a 640 x 480 frame. The tag is found first without it (4 ms), then again with it on
        # the tag's surroundings only, which gives the corners the whole frame would.
        self.finder = cv2.aruco.ArucoDetector(dictionary, cv2.aruco.DetectorParameters())
        self.detector = cv2.aruco.ArucoDetector(dictionary, parameters)
        self.tag_id, self.turn = tag_id, official_turn(family)

    def _find(self, detector, grey: np.ndarray) -> np.ndarray | None:
        corners, ids, _ = detector.detectMarkers(grey)
        if ids is None or self.tag_id not in ids.ravel():
            return None
        return corners[list(ids.ravel()).index(self.tag_id)].reshape(4, 2).astype(np.float64)

    def _refined(self, grey: np.ndarray) -> np.ndarray | None:
        """The tag's four corners, refined (AprilTag's method) on a window around where it was found: the
        tag's bounding box widened by half its size on each side (the white margin and beyond)."""
        rough = self._find(self.finder, grey)
        if rough is None:  # (AprilTag's own search finds some tags the quick one misses)
            return self._find(self.detector, grey)
        low, high = rough.min(axis=0), rough.max(axis=0)
        pad = 0.5 * (high - low).max() + 8
        x0, y0 = np.maximum(np.floor(low - pad).astype(int), 0)
        x1, y1 = np.minimum(np.ceil(high + pad).astype(int) + 1, grey.shape[::-1])
        refined = self._find(self.detector, np.ascontiguousarray(grey[y0:y1, x0:x1]))
        if refined is None:  # (not seen in the window: the whole frame, as before)
            return self._find(self.detector, grey)
        return refined + [x0, y0]

    def corners(self, grey: np.ndarray) -> np.ndarray | None:
        found = self._refined(grey)
        return None if found is None else np.roll(found, -self.turn, axis=0) - 0.5


def make_detector(name: str, family: str, tag_id: int):
    """The detector of that name for the tag; ArsimError where it does not read the family or the id."""
    check_detector(name, family, tag_id)
    return AprilTag3Detector(family, tag_id) if name == "apriltag3" else OpenCVDetector(family, tag_id)
