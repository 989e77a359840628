"""The printed tags are their families' official images: tag36h11's bits against the family's published
codes, read in AprilTag's bit layout; the corner convention against rendered frames; detectors by name."""

import pytest

from arsim.core.tags import TAG_FAMILIES, detector_problem
from arsim.sensors.table import official_tag_image

# AprilTag's published tag36h11 family: the first codes, and where each of the 36 bits (most significant
# first) sits in the 8 x 8 black square, (x, y) from its top-left cell, 1 bits white.
TAG36H11_CODES = {0: 0xD7E00984B, 1: 0xDDA664CA7, 2: 0xDC4A1C821, 3: 0xE17B470E9, 586: 0xE8B772FE0}
TAG36H11_BITS = [(1, 1), (2, 1), (3, 1), (4, 1), (5, 1), (2, 2), (3, 2), (4, 2), (3, 3), (6, 1), (6, 2), (6, 3),
                 (6, 4), (6, 5), (5, 2), (5, 3), (5, 4), (4, 3), (6, 6), (5, 6), (4, 6), (3, 6), (2, 6), (5, 5),
                 (4, 5), (3, 5), (4, 4), (1, 6), (1, 5), (1, 4), (1, 3), (1, 2), (2, 5), (2, 4), (2, 3), (3, 4)]


@pytest.mark.parametrize("tag_id", sorted(TAG36H11_CODES))
def test_the_printed_tag36h11_carries_the_published_code_in_the_official_orientation(tag_id):
    image = official_tag_image("tag36h11", tag_id, 4)
    cells = image.reshape(8, 4, 8, 4).mean(axis=(1, 3)) > 127  # True: white
    assert not cells[0].any() and not cells[-1].any() and not cells[:, 0].any() and not cells[:, -1].any()
    code = 0
    for x, y in TAG36H11_BITS:
        code = (code << 1) | int(cells[y, x])
    assert code == TAG36H11_CODES[tag_id], hex(code)


@pytest.mark.parametrize("detector, family, fragment", [
    ("nosuch", "tag36h11", "unknown detector 'nosuch'"),
    ("apriltag3", "aruco4x4_50", "the apriltag3 detector does not read aruco4x4_50 tags"),
    ("opencv", "tag16h5", None),
])
def test_a_detector_is_checked_against_the_family(detector, family, fragment):
    problem = detector_problem(detector, family, 0)
    assert (problem is None) if fragment is None else (fragment in problem)
    assert "tag16h5 has ids 0 to 29" in detector_problem("opencv", "tag16h5", 30)
    assert TAG_FAMILIES["tag36h11"].cells == 8


@pytest.mark.parametrize("ar, fragment", [
    ('detector = "nosuch"', "[ar] detector"),
    ('detector = "apriltag3"\ntag_family = "aruco4x4_50"', "the apriltag3 detector does not read aruco4x4_50 tags"),
    ('tag_family = "tag16h5"\ntag_id = 40', "tag id 40: tag16h5 has ids 0 to 29"),
])
def test_a_detector_that_cannot_read_the_tag_is_refused_in_one_line(tmp_path, ar, fragment):
    from tests.test_cli import arsim, assert_one_line_error

    path = tmp_path / "bad.toml"
    path.write_text(f"[ar]\n{ar}\n")
    assert_one_line_error(arsim("validate", path), fragment)
    assert_one_line_error(arsim("render", path, "-o", tmp_path / "out"), fragment)
    assert not (tmp_path / "out").exists()
