"""Synthetic IMU: consistent with its trajectory, noise statistics as configured, deterministic."""

from dataclasses import replace

import numpy as np
import pytest

from arsim.core.conventions import CameraIntrinsics
from arsim.core.errors import ArsimError
from arsim.evaluate.allan import allan_deviation, fit_white_and_random_walk
from arsim.sensors.coverage import sphere_coverage
from arsim.sensors.imu import ACCELEROMETER, GYROSCOPE, SensorModel, draw_errors, simulate, simulate_imu
from arsim.sensors.orientation import integrate_gyroscope
from arsim.sensors.trajectory import GRAVITY, CaptureSweep, Static


def test_angular_velocity_is_the_derivative_of_the_orientation():
    sweep = CaptureSweep()
    t = np.array([0.5, 13.3, 30.0, 47.1])
    h = 1e-5
    numeric = (sweep.orientation(t - h).inv() * sweep.orientation(t + h)).as_rotvec() / (2 * h)
    np.testing.assert_allclose(sweep.angular_velocity(t), numeric, atol=1e-8)


def test_integrating_the_noise_free_gyroscope_reproduces_the_orientation():
    sweep = CaptureSweep()
    ideal = SensorModel(rate_hz=200.0, noise_density=0.0)
    stream = simulate("gyroscope", ideal, sweep.angular_velocity, sweep.duration, np.random.default_rng(0))
    t = stream.t_ns / 1e9
    estimate = integrate_gyroscope(t, stream.values, sweep.orientation(t[:1])[0])
    error = (sweep.orientation(t[0::2]).inv() * estimate).magnitude()
    assert error.max() < 1e-6


def test_gyroscope_white_noise_and_random_walk_match_their_settings():
    # The Gauss-Markov bias instability is switched off here: its bump would bias a two-term fit.
    model = replace(GYROSCOPE, bias_instability=0.0)
    static = Static(duration=3 * 3600)
    stream = simulate("gyroscope", model, static.angular_velocity, static.duration, np.random.default_rng(0))
    taus = np.geomspace(0.01, 900, 40)
    adev = allan_deviation(stream.values, model.rate_hz, taus)
    fits = np.array([fit_white_and_random_walk(taus, adev[:, axis]) for axis in range(3)])
    white, walk = fits.mean(axis=0)
    assert white == pytest.approx(model.noise_density, rel=0.10)
    assert walk == pytest.approx(model.bias_random_walk, rel=0.10)


def test_static_accelerometer_reads_gravity_plus_its_bias():
    static = Static(duration=60.0)
    rng = np.random.default_rng(2)
    errors = draw_errors(ACCELEROMETER, np.random.default_rng(3))
    stream = simulate("accelerometer", ACCELEROMETER, static.specific_force, static.duration, rng, errors)
    expected = errors.matrix @ np.array([0.0, 0.0, -GRAVITY[1]]) + errors.turn_on_bias  # flat, screen up: +z
    # What is left is the slow bias terms (Gauss-Markov 2e-3 m/s², random walk) and averaged white noise.
    np.testing.assert_allclose(stream.values.mean(axis=0), expected, atol=0.01)
    assert abs(np.linalg.norm(stream.values.mean(axis=0)) - 9.80665) < 0.8  # within the turn-on bias


def test_same_seed_same_streams_other_seed_other_streams():
    sweep = CaptureSweep(duration=5.0)
    a = simulate_imu(sweep, np.random.default_rng(11))
    b = simulate_imu(sweep, np.random.default_rng(11))
    c = simulate_imu(sweep, np.random.default_rng(12))
    for name in a:
        assert np.array_equal(a[name].values, b[name].values) and np.array_equal(a[name].t_ns, b[name].t_ns)
        assert not np.array_equal(a[name].values, c[name].values)


def test_timestamps_increase_at_the_configured_rates():
    streams = simulate_imu(CaptureSweep(duration=10.0), np.random.default_rng(4))
    for name, rate in (("gyroscope", 200.0), ("accelerometer", 200.0), ("magnetometer", 50.0)):
        t = streams[name].t_ns
        assert np.all(np.diff(t) > 0)
        assert np.mean(np.diff(t)) / 1e9 == pytest.approx(1.0 / rate, rel=1e-3)


def test_the_default_capture_sweep_sees_the_whole_sphere():
    assert sphere_coverage(CaptureSweep(), CameraIntrinsics.from_fov(640, 480, 60.0), fps=30.0) >= 0.99


@pytest.mark.parametrize("bad", [{"noise_density": -1.0}, {"rate_hz": 0.0}, {"jitter_s": -1e-3}])
def test_bad_sensor_settings_are_refused(bad):
    model = replace(GYROSCOPE, **bad)
    with pytest.raises(ArsimError):
        simulate("gyroscope", model, Static().angular_velocity, 1.0, np.random.default_rng(0))


def test_game_rotation_vector_drifts_in_yaw_and_rotation_vector_does_not():
    from arsim.sensors.fusion import mahony, tilt_error_deg, yaw_error_deg

    static = Static(duration=60.0, pitch_deg=-30.0)
    biased = replace(GYROSCOPE, turn_on_bias=0.0)
    streams = simulate_imu(static, np.random.default_rng(5), gyroscope=biased)
    streams["gyroscope"] = replace(streams["gyroscope"], values=streams["gyroscope"].values + np.deg2rad([0.3, 0.3, 0.3]))
    start = static.orientation([0.0])[0]
    results = {}
    for mode in ("game-rotation-vector", "rotation-vector"):
        t, estimate = mahony(streams, start, mode)
        truth = static.orientation(t / 1e9)
        results[mode] = (yaw_error_deg(estimate, truth)[-1], tilt_error_deg(estimate, truth)[-1])
    game_yaw, game_tilt = results["game-rotation-vector"]
    mag_yaw, mag_tilt = results["rotation-vector"]
    assert abs(game_yaw) > 5.0  # 0.3 deg/s on every axis, nothing to stop it
    assert abs(mag_yaw) < 2.0  # the magnetometer holds the heading
    # Gravity holds pitch and roll, up to the accelerometer's own errors: 20 mg turn-on bias per axis
    # (up to 1.6 degrees), 0.6-degree misalignments, and the gyroscope bias over kp (0.3 degrees).
    assert game_tilt < 4.5 and mag_tilt < 4.5


def test_ar_path_circles_the_marker_and_loses_it_only_when_looking_away():
    from arsim.sensors.trajectory import ARPath

    path = ARPath()
    t = np.arange(0.0, path.duration, 1 / 30)
    h = 1e-5
    numeric = (path.orientation(t[::50] - h).inv() * path.orientation(t[::50] + h)).as_rotvec() / (2 * h)
    np.testing.assert_allclose(path.angular_velocity(t[::50]), numeric, atol=1e-7)
    position = path.position(t)
    distance = np.linalg.norm(position, axis=1)
    assert distance.min() == pytest.approx(0.3, abs=1e-6) and distance.max() == pytest.approx(1.5, abs=1e-3)
    assert position[:, 1].min() > 0.1  # above the table
    camera = CameraIntrinsics.from_fov(640, 480, 60.0)
    local = path.camera_orientation(t).inv().apply(-position)  # the marker in camera axes
    px = camera.project(local)
    visible = (local[:, 2] > 0) & (px[:, 0] >= 0) & (px[:, 0] < 640) & (px[:, 1] >= 0) & (px[:, 1] < 480)
    (start, end), = path.look_away
    away = (t > start) & (t < end)
    assert visible[~away].all()
    assert not visible[(t > start + 1) & (t < end - 1)].any()


def test_gauss_markov_recursion_equals_scipys_filter():
    from scipy.signal import lfilter

    from arsim.sensors.imu import _first_order_recursion

    rng = np.random.default_rng(4)
    drive, state, phi = rng.standard_normal((5000, 3)), rng.standard_normal(3), 0.999
    expected, _ = lfilter([1.0], [1.0, -phi], drive, axis=0, zi=(phi * state)[None, :])
    np.testing.assert_allclose(_first_order_recursion(drive, phi, state), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("mode", ["game-rotation-vector", "rotation-vector"])
def test_compiled_fusion_equals_the_scipy_reference(mode):
    from arsim.sensors.fusion import mahony, mahony_reference

    sweep = CaptureSweep(duration=8.0)
    streams = simulate_imu(sweep, np.random.default_rng(21))
    start = sweep.orientation([0.0])[0]
    t, fused = mahony(streams, start, mode, kp=1.0, ki=0.05)
    t_ref, reference = mahony_reference(streams, start, mode, kp=1.0, ki=0.05)
    assert np.array_equal(t, t_ref)
    assert (fused * reference.inv()).magnitude().max() < 1e-12


def test_coverage_cone_pretest_changes_nothing():
    """seen_by_views projects only directions near each view's axis; a projection of every direction in
    every view gives the same answer."""
    from arsim.sensors.coverage import fibonacci_directions, seen_by_views

    camera = CameraIntrinsics.from_fov(160, 120, 40.0, k1=-0.2, k2=0.05)
    views = CaptureSweep(duration=10.0).camera_orientation(np.arange(0.0, 10.0, 0.2))
    directions = fibonacci_directions(3000)
    brute = np.zeros(len(directions), dtype=bool)
    for view in views:
        cam = view.inv().apply(directions)
        ahead = cam[:, 2] > 1e-9
        px = camera.project(np.where(ahead[:, None], cam, 1.0))
        brute |= ahead & (px[:, 0] >= -0.5) & (px[:, 0] <= camera.width - 0.5) \
            & (px[:, 1] >= -0.5) & (px[:, 1] <= camera.height - 0.5)
    seen = seen_by_views(views, camera, directions, chunk=7)
    assert 0.2 < seen.mean() < 0.95 and np.array_equal(seen, brute)
