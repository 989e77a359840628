"""Resampling between equirect and angle map: constants stay constant, energy is kept, spots land right."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from arsim.core.conventions import (
    anglemap_disk_mask,
    anglemap_solid_angles,
    direction_to_anglemap_st,
    direction_to_equirect_uv,
    equirect_solid_angles,
)
from arsim.core.errors import ArsimError
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import (
    anglemap_to_equirect,
    detect_layout,
    equirect_to_anglemap,
    to_layout,
)
from tests.conftest import ENVMAPS

CONSTANT = np.array([0.25, 1.5, 7.0], dtype=np.float32)


def sphere_mean(image: np.ndarray) -> np.ndarray:
    w = anglemap_solid_angles(image.shape[0]) if detect_layout(image) == "anglemap" else equirect_solid_angles(image.shape[0])
    return (image.astype(np.float64) * w[..., None]).sum(axis=(0, 1)) / w.sum()


def test_constant_environment_stays_constant_through_every_conversion():
    eq = np.broadcast_to(CONSTANT, (64, 128, 3)).copy()
    am = equirect_to_anglemap(eq, 96)
    inside = anglemap_disk_mask(96)
    np.testing.assert_allclose(am[inside], np.broadcast_to(CONSTANT, am[inside].shape), rtol=1e-6)
    assert np.all(am[~inside] == 0)
    chain = {
        "am->eq": anglemap_to_equirect(am, 40),
        "am->am (resize)": to_layout(am, "anglemap", 50),
        "eq->eq (resize)": to_layout(eq, "equirect", 33),
        "am->am (rotated)": to_layout(am, "anglemap", 64, Rotation.from_rotvec([0.3, 1.0, -0.2])),
        "eq->am->eq->am": to_layout(anglemap_to_equirect(am, 64), "anglemap", 80),
    }
    for name, image in chain.items():
        valid = anglemap_disk_mask(image.shape[0]) if detect_layout(image) == "anglemap" else np.ones(image.shape[:2], bool)
        assert np.allclose(image[valid], CONSTANT, rtol=1e-6), name
        assert np.all(np.isfinite(image)), name


@pytest.mark.parametrize("path", ENVMAPS, ids=lambda p: p.stem)
def test_round_trip_keeps_the_sphere_mean_radiance_of_real_assets(path):
    eq = read_hdr(path)
    am = equirect_to_anglemap(eq, 512)
    back = anglemap_to_equirect(am, eq.shape[0])
    for image in (am, back):
        rel = np.abs(sphere_mean(image) / sphere_mean(eq) - 1)
        assert rel.max() < 0.01, f"{path.stem}: sphere mean changed by {100 * rel.max():.3f}%"


def test_bright_spot_lands_on_the_texel_the_convention_gives():
    h = 256
    rng = np.random.default_rng(7)
    for _ in range(10):
        row, col = int(rng.integers(20, h - 20)), int(rng.integers(0, 2 * h))
        eq = np.full((h, 2 * h, 3), 0.1, dtype=np.float32)
        eq[row, col] = 1000.0
        u, v = (col + 0.5) / (2 * h), (row + 0.5) / h
        theta, phi = np.pi * v, 2 * np.pi * u
        d = np.array([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)])
        n = 512
        s, t = direction_to_anglemap_st(d)
        expected = (int(np.floor((1 - t) * n)), int(np.floor(s * n)))
        am = equirect_to_anglemap(eq, n)
        peak = np.unravel_index(np.argmax(am[..., 0]), am.shape[:2])
        assert max(abs(peak[0] - expected[0]), abs(peak[1] - expected[1])) <= 1, (row, col, peak, expected)


def test_longitude_wraps_without_a_seam():
    # A smooth function of direction, sampled across the u = 0 / u = 1 seam (the -z meridian).
    h = 64
    eq = np.zeros((h, 2 * h, 3), dtype=np.float32)
    from arsim.core.conventions import equirect_directions

    eq[:] = (1.0 + equirect_directions(h)[..., :1]).astype(np.float32)  # 1 + x, continuous everywhere
    d = np.array([[np.sin(a), 0.0, -np.cos(a)] for a in np.linspace(-0.05, 0.05, 11)])
    uv = direction_to_equirect_uv(d)
    assert uv[:, 0].min() < 0.01 and uv[:, 0].max() > 0.99  # the samples straddle the seam
    from arsim.core.resample import sample_equirect

    np.testing.assert_allclose(sample_equirect(eq, d)[:, 0], 1.0 + d[:, 0], atol=2e-3)


def test_rotation_turns_the_environment():
    eq = np.full((64, 128, 3), 0.1, dtype=np.float32)
    eq[31:33, 63:65] = 100.0  # the texels around +z (centre of the equirect)
    yaw = Rotation.from_rotvec([0, np.pi / 2, 0])  # +z turns to +x
    am = to_layout(eq, "anglemap", 128, yaw)
    peak = np.unravel_index(np.argmax(am[..., 0]), am.shape[:2])
    s, t = direction_to_anglemap_st(np.array([1.0, 0.0, 0.0]))
    assert abs(peak[0] - (1 - t) * 128) < 2 and abs(peak[1] - s * 128) < 2


@pytest.mark.parametrize("shape", [(100, 150, 3), (10, 30, 3), (7, 13, 3)])
def test_aspect_that_is_neither_square_nor_2_to_1_is_refused(shape):
    with pytest.raises(ArsimError, match="neither 1:1"):
        to_layout(np.zeros(shape, np.float32), "anglemap")
