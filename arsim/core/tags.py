"""Fiducial tag families: how each is printed and which detectors read it (README: Conventions, Tags).

A printed tag is its family's official image: for the AprilTag families, the orientation in which
AprilTag's reference decoder reads it (OpenCV 5 draws tag36h11 turned by 180° from it, so arsim turns
OpenCV's drawing back, by the turn the reference decoder reports); for ArUco's, OpenCV's own drawing.
Corners everywhere are in OpenCV's pixel convention (pixel centres at integer coordinates, the top-left
pixel's centre at (0, 0)) and in the order top-left, top-right, bottom-right, bottom-left of the printed
image (its top towards world -z on the table).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2

from arsim.core.errors import ArsimError


@dataclass(frozen=True)
class TagFamily:
    name: str
    opencv_dictionary: int  # cv2.aruco's predefined dictionary
    cells: int  # cells per side of the black square: the data and its one-cell black border
    ids: int  # how many tags the family has
    apriltag: bool  # an AprilTag family (AprilTag's reference decoder reads it); else ArUco's


TAG_FAMILIES = {f.name: f for f in (
    TagFamily("tag36h11", cv2.aruco.DICT_APRILTAG_36h11, 8, 587, True),
    TagFamily("tag25h9", cv2.aruco.DICT_APRILTAG_25h9, 7, 35, True),
    TagFamily("tag16h5", cv2.aruco.DICT_APRILTAG_16h5, 6, 30, True),
    TagFamily("aruco4x4_50", cv2.aruco.DICT_4X4_50, 6, 50, False),
)}

# The detectors by name, and the families each reads: AprilTag 3 (pupil-apriltags) the AprilTag families,
# OpenCV's ArUco module all of them.
DETECTORS = {"apriltag3": tuple(n for n, f in TAG_FAMILIES.items() if f.apriltag), "opencv": tuple(TAG_FAMILIES)}
DEFAULT_DETECTOR = "apriltag3"


def detector_problem(detector: str, family: str, tag_id: int) -> str | None:
    """Why a detector cannot track that tag (None: it can)."""
    if detector not in DETECTORS:
        return f"unknown detector '{detector}'; use one of {', '.join(DETECTORS)}"
    if family not in TAG_FAMILIES:
        return f"unknown tag family '{family}'; use one of {', '.join(TAG_FAMILIES)}"
    if family not in DETECTORS[detector]:
        readers = [d for d, families in DETECTORS.items() if family in families]
        return (f"the {detector} detector does not read {family} tags (it reads {', '.join(DETECTORS[detector])}); "
                f"use detector = \"{readers[0]}\" or another family")
    if not 0 <= tag_id < TAG_FAMILIES[family].ids:
        return f"tag id {tag_id}: {family} has ids 0 to {TAG_FAMILIES[family].ids - 1}"
    return None


def check_detector(detector: str, family: str, tag_id: int) -> None:
    problem = detector_problem(detector, family, tag_id)
    if problem:
        raise ArsimError(problem)


def apriltag_detector(family: str, **options):
    """pupil-apriltags' Detector for one family, destroyed in the right order: its own __del__ frees the
    family before the detector, whose destruction still reads the family's decoding table (heap corruption,
    seen as "malloc(): mismatching next->prev_size" once in a few runs)."""
    import pupil_apriltags

    class Detector(pupil_apriltags.Detector):
        def __del__(self):
            pointer, self.tag_detector_ptr = getattr(self, "tag_detector_ptr", None), None
            if pointer is not None:
                self.libc.apriltag_detector_destroy.restype = None
                self.libc.apriltag_detector_destroy(pointer)
                for name, f in self.tag_families.items():
                    getattr(self.libc, f"{name}_destroy").restype = None
                    getattr(self.libc, f"{name}_destroy")(f)

    return Detector(families=family, **options)
