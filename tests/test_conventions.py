"""The pinned conventions (README: Conventions): projections, their inverses, solid angles, cameras."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from arsim.core.conventions import (
    CameraIntrinsics,
    OPENCV_TO_OPENGL,
    angle_between,
    anglemap_directions,
    anglemap_disk_mask,
    anglemap_solid_angles,
    anglemap_st_to_direction,
    anglemap_texel_st,
    direction_to_anglemap_st,
    direction_to_equirect_uv,
    equirect_directions,
    equirect_solid_angles,
    equirect_uv_to_direction,
    gl_projection_from_intrinsics,
    gl_view_from_opencv_pose,
)

ROUND_TRIP_TOL = 1e-9  # radians


def sphere_direction(z: float, phi: float) -> np.ndarray:
    """Unit direction from its z component and azimuth: uniform on the sphere for uniform z, phi."""
    r = np.sqrt(max(0.0, 1.0 - z * z))
    return np.array([r * np.cos(phi), r * np.sin(phi), z])


directions = st.builds(
    sphere_direction,
    st.floats(-1.0, 1.0, allow_nan=False),
    st.floats(0.0, 2 * np.pi, allow_nan=False),
)
# Directions within 1e-6 rad of -z (and of the poles): where acos and the azimuth are ill-conditioned.
near_minus_z = st.builds(
    lambda angle, phi: np.array([np.sin(angle) * np.cos(phi), np.sin(angle) * np.sin(phi), -np.cos(angle)]),
    st.floats(0.0, 1e-6, allow_nan=False),
    st.floats(0.0, 2 * np.pi, allow_nan=False),
)


def random_directions(n: int, seed: int = 1) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@settings(max_examples=500)
@given(st.one_of(directions, near_minus_z))
def test_anglemap_round_trip_is_exact(d):
    back = anglemap_st_to_direction(direction_to_anglemap_st(d))
    assert angle_between(d, back) < ROUND_TRIP_TOL


def test_anglemap_round_trip_over_a_million_directions_and_next_to_minus_z():
    d = random_directions(1_000_000)
    tiny = np.array([1e-6, 1e-7, 1e-9, 1e-12, 0.0])
    phis = np.linspace(0, 2 * np.pi, 7)
    a, p = np.meshgrid(tiny, phis)
    near = np.stack([np.sin(a) * np.cos(p), np.sin(a) * np.sin(p), -np.cos(a)], axis=-1).reshape(-1, 3)
    for batch in (d, near):
        err = angle_between(batch, anglemap_st_to_direction(direction_to_anglemap_st(batch)))
        assert np.all(np.isfinite(err))
        assert err.max() < ROUND_TRIP_TOL


def test_anglemap_poles_have_no_nan_and_follow_the_convention():
    st_ = direction_to_anglemap_st(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]]))
    assert np.all(np.isfinite(st_))
    np.testing.assert_allclose(st_[0], [0.5, 0.5])  # +z: image centre
    np.testing.assert_allclose(st_[1], [0.5, 1.0])  # -z: the rim (Alg. 2.2, line 10)
    d = anglemap_st_to_direction(np.array([[0.5, 0.5], [0.5, 1.0], [1.0, 0.5], [0.0, 0.0]]))
    assert np.all(np.isfinite(d))
    np.testing.assert_allclose(d[0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(d[1], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(d[2], [0, 0, -1], atol=1e-15)  # right edge of the disk is -z too
    np.testing.assert_allclose(np.linalg.norm(d[3]), 1.0)  # outside the disk: clamped to the rim


def test_anglemap_axes_right_is_plus_x_up_is_plus_y():
    # 90 degrees from +z lands half way to the rim: rho = 0.5.
    st_ = direction_to_anglemap_st(np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0], [0, -1.0, 0]]))
    np.testing.assert_allclose(st_, [[0.75, 0.5], [0.5, 0.75], [0.25, 0.5], [0.5, 0.25]], atol=1e-15)


def test_anglemap_matches_the_formula_of_the_convention():
    d = random_directions(1000, seed=2)
    d = d[d[:, 2] > -0.999]
    r = np.arccos(d[:, 2]) / (np.pi * np.sqrt(d[:, 0] ** 2 + d[:, 1] ** 2))
    expected = np.stack([0.5 + d[:, 0] * r / 2, 0.5 + d[:, 1] * r / 2], axis=-1)
    np.testing.assert_allclose(direction_to_anglemap_st(d), expected, atol=1e-12)


def test_anglemap_texel_centres():
    st_ = anglemap_texel_st(4)
    np.testing.assert_allclose(st_[0, 0], [0.125, 0.875])  # row 0 = top of the file: t near 1
    np.testing.assert_allclose(st_[3, 2], [0.625, 0.125])


@pytest.mark.parametrize("n", [64, 512, 1024])
def test_anglemap_solid_angles_sum_to_4pi(n):
    total = anglemap_solid_angles(n).sum()
    assert abs(total / (4 * np.pi) - 1) < 1e-3


def test_anglemap_solid_angles_follow_sinc_and_vanish_outside():
    n = 512
    w = anglemap_solid_angles(n)
    assert np.all(w[~anglemap_disk_mask(n)] == 0)
    assert np.all(w[anglemap_disk_mask(n)] > 0)
    centre = w[n // 2, n // 2]
    rho = np.hypot(1 / n, 1 / n)
    assert centre == pytest.approx((2 * np.pi / n) ** 2 * np.sin(np.pi * rho) / (np.pi * rho), rel=1e-12)


@settings(max_examples=500)
@given(st.one_of(directions, near_minus_z))
def test_equirect_round_trip_is_exact(d):
    back = equirect_uv_to_direction(direction_to_equirect_uv(d))
    assert angle_between(d, back) < ROUND_TRIP_TOL


def test_equirect_round_trip_over_a_million_directions_and_at_the_poles():
    d = random_directions(1_000_000, seed=3)
    poles = np.array([[0, 1.0, 0], [0, -1.0, 0], [1e-12, 1.0, 0], [0, -1.0, 1e-9]])
    poles /= np.linalg.norm(poles, axis=1, keepdims=True)
    for batch in (d, poles):
        uv = direction_to_equirect_uv(batch)
        assert np.all((uv >= 0) & (uv <= 1)) and np.all(uv[:, 0] < 1)
        assert angle_between(batch, equirect_uv_to_direction(uv)).max() < ROUND_TRIP_TOL


def test_equirect_centre_column_looks_along_plus_z():
    d = equirect_uv_to_direction(np.array([[0.5, 0.5], [0.75, 0.5], [0.0, 0.5], [0.3, 0.0]]))
    np.testing.assert_allclose(d[0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(d[1], [-1, 0, 0], atol=1e-15)  # phi = 3pi/2
    np.testing.assert_allclose(d[2], [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(d[3], [0, 1, 0], atol=1e-15)  # top row: +y


@pytest.mark.parametrize("h", [16, 256, 512])
def test_equirect_solid_angles_sum_to_4pi(h):
    w = equirect_solid_angles(h)
    assert w.shape == (h, 2 * h)
    assert abs(w.sum() / (4 * np.pi) - 1) < 1e-12


def test_texel_directions_are_unit_and_finite():
    for d in (anglemap_directions(128), equirect_directions(64)):
        assert np.all(np.isfinite(d))
        np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12)


# ----------------------------------------------------------------------------------------------
# Cameras


def test_pinhole_project_unproject_round_trip():
    k = CameraIntrinsics.from_fov(640, 480, 60.0)
    px = np.random.default_rng(4).uniform([0, 0], [640, 480], size=(100, 2))
    rays = k.unproject(px)
    np.testing.assert_allclose(np.linalg.norm(rays, axis=1), 1.0)
    np.testing.assert_allclose(k.project(rays * 3.7), px, atol=1e-9)
    # 60 degrees horizontal field of view: the left and right image edges are 30 degrees off axis.
    edge = k.unproject(np.array([[-0.5, k.cy], [639.5, k.cy]]))
    np.testing.assert_allclose(np.degrees(np.arctan2(edge[:, 0], edge[:, 2])), [-30, 30], atol=1e-9)


def test_gl_projection_puts_points_where_opencv_does():
    k = CameraIntrinsics(640, 480, 500.0, 510.0, 300.2, 250.7)
    rng = np.random.default_rng(5)
    world = rng.uniform([-1, -1, 1], [1, 1, 5], size=(50, 3))
    rot = Rotation.from_rotvec([0.1, -0.2, 0.05])
    t = np.array([0.1, 0.2, 0.3])
    cam = rot.apply(world) + t
    keep = cam[:, 2] > 0.1
    pixels = k.project(cam[keep])

    view = gl_view_from_opencv_pose(rot, t)
    proj = gl_projection_from_intrinsics(k, near=0.05, far=100.0)
    clip = (proj @ view @ np.c_[world[keep], np.ones(keep.sum())].T).T
    ndc = clip[:, :3] / clip[:, 3:]
    win_x = (ndc[:, 0] + 1) / 2 * k.width
    win_y = (ndc[:, 1] + 1) / 2 * k.height
    # GL window coordinates: origin bottom left, pixel centres at half-integers.
    np.testing.assert_allclose(win_x, pixels[:, 0] + 0.5, atol=1e-9)
    np.testing.assert_allclose(win_y, k.height - (pixels[:, 1] + 0.5), atol=1e-9)
    assert np.all(np.abs(ndc[:, 2]) <= 1)


def test_opencv_to_opengl_flips_y_and_z():
    np.testing.assert_array_equal(OPENCV_TO_OPENGL @ [0, 0, 1], [0, 0, -1])  # forward is -z in GL
    np.testing.assert_array_equal(OPENCV_TO_OPENGL @ [0, 1, 0], [0, -1, 0])  # down is -y in GL


def test_radial_distortion_round_trips_and_matches_opencv():
    import cv2

    k = CameraIntrinsics.from_fov(640, 480, 70.0, k1=-0.12, k2=0.03)
    px = np.random.default_rng(8).uniform([0, 0], [640, 480], size=(200, 2))
    rays = k.unproject(px)
    np.testing.assert_allclose(k.project(rays), px, atol=1e-6)
    projected, _ = cv2.projectPoints(rays.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k.matrix, k.distortion)
    np.testing.assert_allclose(projected[:, 0], k.project(rays), atol=1e-9)
