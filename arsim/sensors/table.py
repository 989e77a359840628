"""The real objects of the AR scene: a table top at y = 0 with a printed AprilTag at its centre.

Both are matte (Lambertian) and lit by the same environment as everything else, at infinity: their
radiance is reflectance x M_1(+y), the environment's normalised cosine average over the upper
hemisphere (README: Conventions; E/pi). Shadows and the lower hemisphere play no part for a surface
facing up. The tag is its family's official image (core/tags.py): its x axis (image columns) along world
+x, its image top towards world -z, its normal +y.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache, cached_property

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles
from arsim.core.tags import TAG_FAMILIES, apriltag_detector
from arsim.scenario.sections import ArSection

INK, PAPER = 0.03, 0.80  # diffuse reflectances of printed black and of white paper
CELL_TEXELS = 16


@dataclass(frozen=True)
class Table:
    tag_family: str = "tag36h11"
    tag_id: int = 0
    tag_size_m: float = 0.16  # side of the black square (what pose estimation measures)
    margin_cells: float = 1.0  # white paper around it
    size_m: tuple[float, float] = (1.6, 1.0)  # along world x and z
    albedo: tuple[float, float, float] = (0.30, 0.20, 0.12)

    @classmethod
    def of(cls, section: ArSection) -> Table:
        return cls(section.tag_family, section.tag_id, section.tag_size_m, section.tag_margin_cells,
                   tuple(section.table_size_m), tuple(section.table_albedo))

    @property
    def paper_half_m(self) -> float:
        """Half the side of the printed sheet (tag plus margin)."""
        cells = TAG_FAMILIES[self.tag_family].cells
        return self.tag_size_m / 2 * (cells + 2 * self.margin_cells) / cells

    @cached_property
    def paper_image(self) -> np.ndarray:
        """Reflectance (P, P) float32 of the printed sheet, row 0 towards world -z: the family's official image
        (core/tags.py) in a white margin."""
        tag = official_tag_image(self.tag_family, self.tag_id, CELL_TEXELS)
        margin = int(round(self.margin_cells * CELL_TEXELS))
        sheet = np.pad(tag, margin, constant_values=255)
        return np.where(sheet > 127, PAPER, INK).astype(np.float32)

    def tag_corners_world(self) -> np.ndarray:
        """(4, 3) world corners of the black square in OpenCV's order: top-left, top-right, bottom-right,
        bottom-left of the tag image."""
        h = self.tag_size_m / 2
        return np.array([[-h, 0.0, -h], [h, 0.0, -h], [h, 0.0, h], [-h, 0.0, h]])


def official_tag_image(family: str, tag_id: int, cell_texels: int) -> np.ndarray:
    """The tag's black square (uint8, cells x cell_texels on a side) in its family's official orientation:
    OpenCV's drawing turned by official_turn."""
    f = TAG_FAMILIES[family]
    drawn = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(f.opencv_dictionary), tag_id,
                                          f.cells * cell_texels, borderBits=1)
    return np.ascontiguousarray(np.rot90(drawn, official_turn(family)))


@cache
def official_turn(family: str) -> int:
    """Quarter turns (counter-clockwise, np.rot90's k) that bring OpenCV's drawing of a family's tags to the
    official image: for the AprilTag families, the turn that puts the corner AprilTag's reference decoder
    (pupil-apriltags) reads as the official top-left (its fourth, the corners wrapping counter-clockwise from
    the bottom-left) at the top-left; 0 for ArUco's, whose drawing OpenCV defines. OpenCV 5 draws tag36h11
    turned by 2."""
    f = TAG_FAMILIES[family]
    if not f.apriltag:
        return 0

    drawn = cv2.aruco.generateImageMarker(cv2.aruco.getPredefinedDictionary(f.opencv_dictionary), 0, f.cells * 8, borderBits=1)
    image = np.pad(drawn, 16, constant_values=255)
    found = [d for d in apriltag_detector(family).detect(image) if d.tag_id == 0]
    if not found:
        raise RuntimeError(f"AprilTag's decoder does not read OpenCV's {family} drawing")
    side = f.cells * 8
    drawn_corners = 16 - 0.5 + np.array([[0, 0], [side, 0], [side, side], [0, side]])  # TL, TR, BR, BL (AprilTag's pixels)
    where = int(np.argmin(np.linalg.norm(drawn_corners - found[0].corners[3], axis=1)))
    return where  # the official top-left drawn at TL (0), TR (1: a quarter turn back), BR (2), BL (3)


def upward_light(probe: np.ndarray) -> np.ndarray:
    """M_1(+y) (RGB) of an angle map: the radiance a white Lambertian surface facing up reflects."""
    n = probe.shape[0]
    inside = anglemap_disk_mask(n)
    cosine = np.maximum(anglemap_directions(n)[inside][:, 1], 0.0) * anglemap_solid_angles(n)[inside]
    return (cosine @ probe[inside].astype(np.float64)) / cosine.sum()


def table_radiance_reference(table: Table, light: np.ndarray, hits_xz: np.ndarray) -> np.ndarray:
    """Radiance (K, 3) at table points (K, 2) (x, z): tag sheet reflectance (bilinear, texel centres as
    GL samples them) or the table's, times the light; NaN off the table."""
    image = table.paper_image
    size = image.shape[0]
    half = table.paper_half_m
    uv = (hits_xz + half) / (2 * half)  # u along +x, v along +z (image rows)
    on_paper = np.all((uv >= 0) & (uv <= 1), axis=1)
    col, row = uv[:, 0] * size - 0.5, uv[:, 1] * size - 0.5
    paper = map_coordinates(image, [row, col], order=1, mode="nearest")
    reflectance = np.where(on_paper[:, None], paper[:, None], np.asarray(table.albedo)[None, :])
    on_table = np.all(np.abs(hits_xz) <= np.asarray(table.size_m) / 2, axis=1)
    return np.where(on_table[:, None], reflectance * light[None, :], np.nan)
