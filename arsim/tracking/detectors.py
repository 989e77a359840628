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


# The tag is looked for first round where it was last found: the frame outside a window about its last corners
# (grown by WINDOW_GROWTH of the tag's size and WINDOW_PAD_PX, on the quad search's tile grid) is set to one flat
# grey, which AprilTag's thresholding leaves out. The frame keeps its size, so the detector computes in the same
# coordinates on the same pixels: the same corners to the bit (the default, indoor, outdoor_sun, quick, night and
# lost_tag AR paths, every frame) in a third to two thirds of the time. A tag found too near the window's edge, or
# none, and the whole frame is searched.
WINDOW_GROWTH = 0.5
WINDOW_PAD_PX = 16
WINDOW_EDGE_PX = 8  # a tag's corners must lie this far inside the window's masked edges
FLAT = 127


class AprilTag3Detector:
    def __init__(self, family: str, tag_id: int, decimate: float = 2.0):
        self.tag_id = tag_id
        # its quads fitted and decoded on every core: the same corners as on one thread (the detections are
        # sorted by id before they are returned; one tag per id in a frame), a 640 x 480 frame in 30 % less
        # wall time on two cores
        self.detector = apriltag_detector(family, nthreads=os.cpu_count() or 1, quad_decimate=decimate,
                                          refine_edges=1)
        self.tile = int(4 * max(decimate, 1.0))  # AprilTag's threshold tiles are 4 pixels of the decimated image
        self.last: np.ndarray | None = None  # the corners last found
        self._masked: np.ndarray | None = None

    def corners(self, grey: np.ndarray) -> np.ndarray | None:
        grey = np.ascontiguousarray(grey)
        if self.last is not None:
            window = self._window(grey.shape, self.last)
            if window != (0, 0, grey.shape[1], grey.shape[0]):  # (a tag that fills the frame: the frame is the window)
                found = self._in_window(grey, window)
                if found is not None:
                    self.last = found
                    return found
        self.last = self._find(grey)
        return self.last

    def _find(self, grey: np.ndarray) -> np.ndarray | None:
        for d in self.detector.detect(grey):
            if d.tag_id == self.tag_id:
                # AprilTag's corners wrap counter-clockwise from the official bottom-left: reversed, the fourth
                # (the top-left) first
                return d.corners[::-1].astype(np.float64) - 0.5
        return None

    def _window(self, shape: tuple[int, int], last: np.ndarray) -> tuple[int, int, int, int]:
        """(x0, y0, x1, y1), exclusive: the window about the corners `last`, on the threshold tiles' grid."""
        h, w = shape
        low, high = last.min(axis=0), last.max(axis=0)
        pad = WINDOW_GROWTH * float((high - low).max()) + WINDOW_PAD_PX
        t = self.tile
        x0, y0 = (max(int((v - pad) // t) * t, 0) for v in low)
        return x0, y0, min(int(-(-(high[0] + pad) // t)) * t, w), min(int(-(-(high[1] + pad) // t)) * t, h)

    def _in_window(self, grey: np.ndarray, window: tuple[int, int, int, int]) -> np.ndarray | None:
        """The tag found in the frame with everything outside the window flat; None where it is not, or lies too
        near one of the window's masked edges."""
        h, w = grey.shape
        x0, y0, x1, y1 = window
        if self._masked is None or self._masked.shape != grey.shape:
            self._masked = np.empty_like(grey)
        masked = self._masked
        masked.fill(FLAT)
        masked[y0:y1, x0:x1] = grey[y0:y1, x0:x1]
        found = self._find(masked)
        if found is None:
            return None
        e = WINDOW_EDGE_PX
        inside = ((x0 == 0 or found[:, 0].min() >= x0 + e) and (x1 == w or found[:, 0].max() <= x1 - 1 - e)
                  and (y0 == 0 or found[:, 1].min() >= y0 + e) and (y1 == h or found[:, 1].max() <= y1 - 1 - e))
        return found if inside else None


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
