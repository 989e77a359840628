"""The camera model: response curves invert, noise is physical, auto-exposure settles in time."""

import numpy as np
import pytest

from arsim.core.errors import ArsimError
from arsim.sensors.camera import (LUMA, RESPONSES, AutoExposure, ResponseCurve, SensorSettings, expose, metered_level, metering, noise_key,
                                  pixel_normals, vignette)


@pytest.mark.parametrize("kind", RESPONSES)
def test_response_curves_are_monotonic_and_invert(kind):
    curve = ResponseCurve(kind)
    x = np.linspace(0, 1, 2001)
    y = curve.apply(x)
    assert y[0] == pytest.approx(0, abs=1e-12) and y[-1] == pytest.approx(1, abs=1e-12)
    assert np.all(np.diff(y) > 0)
    np.testing.assert_allclose(curve.inverse(y), x, atol=1e-9)


def test_unknown_response_is_refused():
    with pytest.raises(ArsimError, match="response curve 'film'"):
        ResponseCurve("film")


def test_shot_noise_grows_with_the_square_root_of_the_signal():
    sensor = SensorSettings(vignetting=0.0, read_noise_e=0.0)
    curve = ResponseCurve("gamma", gamma=1.0)  # linear, to read the noise directly
    stds = []
    for k, level in enumerate((0.1, 0.4)):
        radiance = np.full((200, 200, 3), level / (sensor.sensitivity * 0.01))
        normals = pixel_normals(noise_key(0, "capture", k), 200, 200)
        frame = expose(radiance, 0.01, sensor.base_iso, sensor, curve, normals).astype(float) / 255
        stds.append(frame.std())
        assert frame.mean() == pytest.approx(level, abs=0.004)
    expected = [np.sqrt(level * sensor.full_well_e) / sensor.full_well_e for level in (0.1, 0.4)]
    np.testing.assert_allclose(stds, expected, rtol=0.1)  # plus a little from 8-bit quantisation


def test_vignetting_is_one_at_the_centre_and_falls_to_the_corners():
    v = vignette(101, 201, 0.3)
    assert v[50, 100] == pytest.approx(1.0)
    assert v[0, 0] == pytest.approx(0.7) and v[-1, -1] == pytest.approx(0.7)


@pytest.mark.parametrize("dark, bright", [(0.05, 20.0), (0.5, 500.0), (0.005, 5000.0), (20.0, 0.05)])
def test_auto_exposure_settles_within_its_configured_frames(dark, bright):
    sensor, curve = SensorSettings(), ResponseCurve()
    ae = AutoExposure(sensor, curve)
    falloff = vignette(48, 64, sensor.vignetting)
    levels, settings, extreme = [], [], []
    for k in range(80):
        scene = np.full((48, 64, 3), dark if k < 40 else bright)
        used = ae.next_frame_settings()
        frame = expose(scene, *used, sensor, curve, pixel_normals(noise_key(1, "capture", k), 48, 64), falloff)
        ae.update(frame, used)
        levels.append(metered_level(frame, curve))
        settings.append(used)
        extreme.append(np.all(frame == 255) or np.all(frame == 0))
    after = np.array(levels[40:])
    within = np.abs(after / sensor.target_grey - 1) < 0.10
    assert within[sensor.settle_frames:].all(), after
    # Never all white or all black for longer than the settling time.
    run = longest = 0
    for e in extreme:
        run = run + 1 if e else 0
        longest = max(longest, run)
    assert longest <= sensor.settle_frames
    exposures, isos = np.array(settings).T
    assert exposures.min() >= sensor.exposure_range_s[0] and exposures.max() <= sensor.exposure_range_s[1]
    assert isos.min() >= sensor.iso_range[0] and isos.max() <= sensor.iso_range[1]


def test_auto_exposure_stays_within_limits_when_the_scene_is_too_dark():
    sensor, curve = SensorSettings(), ResponseCurve()
    ae = AutoExposure(sensor, curve)
    for k in range(30):
        used = ae.next_frame_settings()
        ae.update(expose(np.full((16, 16, 3), 1e-4), *used, sensor, curve, pixel_normals(noise_key(2, "capture", k), 16, 16)),
                  used)
    assert used == (sensor.exposure_range_s[1], sensor.iso_range[1])


def test_bad_sensor_settings_are_refused():
    with pytest.raises(ArsimError):
        AutoExposure(SensorSettings(iso_range=(200.0, 100.0)), ResponseCurve())
    with pytest.raises(ArsimError):
        AutoExposure(SensorSettings(convergence=0.0), ResponseCurve())


@pytest.mark.parametrize("kind, gamma", [("srgb", 2.2), ("gamma", 2.2), ("gamma", 4.0), ("s-curve", 2.2)])
def test_8_bit_encoding_equals_rounding_the_curve(kind, gamma):
    curve = ResponseCurve(kind, gamma=gamma)
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.random(200000) * 1.2, rng.random(50000) * 1e-3, [-1.0, 0.0, 1.0, 2.0]])
    np.testing.assert_array_equal(curve.encode(x), np.round(curve.apply(x) * 255).astype(np.uint8))


@pytest.mark.parametrize("kind, gamma", [("srgb", 2.2), ("s-curve", 2.2), ("gamma", 10.0), ("gamma", 0.1)])
def test_the_shader_code_guesses_are_within_their_stated_steps(kind, gamma):
    curve = ResponseCurve(kind, gamma=gamma)
    bins = 1024
    packed, steps = curve.guess_table(bins)
    guesses = (packed[:, None] >> np.array([0, 8, 16, 24], dtype=np.uint32)).ravel() & 255
    x = np.concatenate([np.random.default_rng(3).random(300000), np.random.default_rng(4).random(100000) * 1e-4])
    bin_of_x = np.minimum((np.sqrt(x.astype(np.float32)) * bins).astype(int), bins - 1)
    off = np.abs(guesses[bin_of_x].astype(int) - curve.encode(x))
    assert off.max() <= steps
    assert (steps == 1) == (kind != "gamma" or 0.5 <= gamma <= 2.6)  # one step for the usual curves


@pytest.mark.parametrize("kind, gamma, contrast", [("srgb", 2.2, 2.0), ("s-curve", 2.2, 2.0), ("s-curve", 2.2, 0.5),
                                                    ("gamma", 2.2, 2.0), ("gamma", 1.0, 2.0), ("gamma", 10.0, 2.0)])
def test_the_shader_one_comparison_codes_equal_the_curve_s_codes(kind, gamma, contrast):
    """ResponseCurve.step_table, the GL camera's codes in one comparison: every float32 value in [0, 1] gets
    lowest + (x >= step) = encode(x), its bin found by a float32 sqrt that may be an ulp off either way; the
    values next to each threshold (within 4 ulp) included. A steep curve has no such table."""
    curve = ResponseCurve(kind, gamma=gamma, contrast=contrast)
    bins = 1024
    table = curve.step_table(bins)
    if kind == "gamma" and gamma == 10.0:
        assert table is None  # (its dark codes are far denser than the bins)
        return
    assert table is not None
    packed, steps = table
    lowest = (packed[:, None] >> np.array([0, 8, 16, 24], dtype=np.uint32)).ravel() & 255
    rng = np.random.default_rng(5)
    t = curve.thresholds_float32()
    near = (t[:, None].view(np.int32) + np.arange(-4, 5, dtype=np.int32)).view(np.float32).ravel()
    x = np.concatenate([rng.random(300000), rng.random(100000) * 1e-4, near, [0.0, 1.0]]).astype(np.float32)
    x = x[(x >= 0) & (x <= 1)]
    root = np.sqrt(x)
    for off in (-1, 0, 1):  # (an ulp off)
        r = np.nextafter(root, np.float32(np.inf) if off > 0 else np.float32(0)) if off else root
        b = np.minimum((r * np.float32(bins)).astype(np.int64), bins - 1)
        np.testing.assert_array_equal(lowest[b] + (x >= steps[b]), curve.encode(x.astype(np.float64)))


@pytest.mark.parametrize("shape", [(480, 640), (61, 83)])
def test_compiled_metering_equals_the_numpy_formula(shape):
    rgba = np.random.default_rng(2).integers(0, 256, shape + (4,), dtype=np.uint8)
    rgba[: shape[0] // 3] = 255  # some clipped rows
    frame, curve = rgba[..., :3], ResponseCurve()  # a strided view, as read back from GL
    grid = frame[::4, ::4]
    y, x = np.mgrid[0:grid.shape[0], 0:grid.shape[1]]
    weight = np.exp(-(((x - grid.shape[1] / 2) / (0.35 * grid.shape[1])) ** 2 + ((y - grid.shape[0] / 2) / (0.35 * grid.shape[0])) ** 2))
    level = float(((curve.decode(grid) @ LUMA) * weight / weight.sum()).sum())
    got = metering(frame, curve)
    assert got[0] == pytest.approx(level, rel=1e-12) and metered_level(frame, curve) == got[0]
    assert got[1] == np.mean(grid >= 255) and got[2] == np.mean(grid <= 0)


def test_hashed_pixel_normals_are_standard_normal_and_independent():
    from scipy import stats

    a = pixel_normals(noise_key(0, "capture", 0), 240, 320).ravel()
    b = pixel_normals(noise_key(0, "capture", 1), 240, 320).ravel()
    assert abs(a.mean()) < 0.01 and abs(a.std() - 1) < 0.01
    assert stats.kstest(a, "norm").pvalue > 1e-3  # the Box-Muller output is Gaussian
    assert abs(np.corrcoef(a, b)[0, 1]) < 0.01  # frames draw different noise
    assert abs(np.corrcoef(a[:-1], a[1:])[0, 1]) < 0.01  # neighbouring samples too
    assert not np.array_equal(pixel_normals(noise_key(1, "capture", 0), 4, 4), pixel_normals(noise_key(0, "capture", 0), 4, 4))
    assert noise_key(0, "capture", 3) != noise_key(0, "burst", 3)
