"""The real objects of the AR scene: a table top at y = 0 with a printed AprilTag at its centre.

Both are matte (Lambertian) and lit by the same environment as everything else, at infinity: their
radiance is reflectance x M_1(+y), the environment's normalised cosine average over the upper
hemisphere (README: Conventions; E/pi). Shadows and the lower hemisphere play no part for a surface
facing up. The tag image follows the marker frame OpenCV's pose estimation uses: its x axis (image
columns) along world +x, its image top towards world -z, its normal +y.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import cv2
import numpy as np
from scipy.ndimage import map_coordinates

from arsim.core.conventions import anglemap_directions, anglemap_disk_mask, anglemap_solid_angles
from arsim.scenario.sections import ArSection

TAG_DICTIONARIES = {"tag36h11": cv2.aruco.DICT_APRILTAG_36h11}
TAG_CELLS = 8  # tag36h11: 6 x 6 data cells inside a one-cell black border
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
        return self.tag_size_m / 2 * (TAG_CELLS + 2 * self.margin_cells) / TAG_CELLS

    @cached_property
    def paper_image(self) -> np.ndarray:
        """Reflectance (P, P) float32 of the printed sheet, row 0 towards world -z."""
        dictionary = cv2.aruco.getPredefinedDictionary(TAG_DICTIONARIES[self.tag_family])
        tag = cv2.aruco.generateImageMarker(dictionary, self.tag_id, TAG_CELLS * CELL_TEXELS, borderBits=1)
        margin = int(round(self.margin_cells * CELL_TEXELS))
        sheet = np.pad(tag, margin, constant_values=255)
        return np.where(sheet > 127, PAPER, INK).astype(np.float32)

    def tag_corners_world(self) -> np.ndarray:
        """(4, 3) world corners of the black square in OpenCV's order: top-left, top-right, bottom-right,
        bottom-left of the tag image."""
        h = self.tag_size_m / 2
        return np.array([[-h, 0.0, -h], [h, 0.0, -h], [h, 0.0, h], [-h, 0.0, h]])


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
