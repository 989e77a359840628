"""The capture stage: compiled accumulation against its NumPy oracle, a perfect sensor reproducing the
truth, alignment finding a known rotation, featureless frames changing nothing, and bad inputs."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from arsim.capture.accumulate import (CHUNK, ProbeAccumulator, SensorNoise, _chunks_in_view, accumulate_reference,
                                     clip_corrected)
from arsim.capture.align import Aligner
from arsim.capture.response import RecoveredResponse, calibrate_response, response_error
from arsim.core.conventions import CameraIntrinsics, anglemap_directions, anglemap_disk_mask
from arsim.core.hdr_io import read_hdr
from arsim.core.resample import to_layout
from arsim.sensors.camera import ResponseCurve, SensorSettings, expose, pixel_normals
from arsim.sensors.trajectory import CaptureSweep
from arsim.sensors.views import environment_view_reference
from tests.conftest import ENVMAPS
from tests.test_cli import arsim, assert_one_line_error
from tests.test_recording import SHORT

TRUE_CURVE = ResponseCurve()


def ideal_frame(probe, camera, rotation, exposure_scale):
    """Noise-free 8-bit frame without vignetting: the true curve applied to radiance x exposure."""
    radiance = environment_view_reference(probe, camera, rotation)
    return TRUE_CURVE.encode(radiance * exposure_scale), radiance


def known_probe(probe, camera):
    """An accumulator holding a known probe (every disk texel measured once)."""
    acc = ProbeAccumulator(probe.shape[0], camera, np.ones((camera.height, camera.width)))
    inside = anglemap_disk_mask(probe.shape[0])[..., None]
    acc.sums[0], acc.weights[0] = probe * inside, np.broadcast_to(inside, probe.shape)
    acc.unclipped_votes[0] = acc.weights[0]
    acc.radiance[:] = np.where(inside, probe, -1.0)
    return acc


def ideal_response():
    return RecoveredResponse(np.repeat(TRUE_CURVE.decode(np.arange(256))[:, None], 3, axis=1))


@pytest.mark.parametrize("level", [0, 1])
def test_compiled_accumulation_equals_the_numpy_oracle(level):
    camera = CameraIntrinsics.from_fov(120, 90, 70.0, k1=-0.05, k2=0.01)
    falloff = np.linspace(0.7, 1.0, 120 * 90).reshape(90, 120)
    codes = np.random.default_rng(1).integers(0, 256, (90, 120, 3), dtype=np.uint8)
    codes[:20] = 255  # clipped rows
    radiance_of_code = np.random.default_rng(2).random((256, 3)) + 0.1
    rotation = Rotation.from_euler("xyz", [20, -130, 5], degrees=True).as_matrix()
    sensor = SensorNoise(6000.0, 3.0)
    acc = ProbeAccumulator(64, camera, falloff, levels=2, sensor=sensor)
    acc.add(codes, radiance_of_code, rotation, 0.6, level, gain=4.0)
    reference = accumulate_reference(64, camera, falloff, codes, radiance_of_code, rotation, 0.6, level, 4.0, sensor)
    for compiled, oracle in zip(acc.levels, reference):
        assert (oracle > 0).sum() > 100 and not compiled[1 - level].any()
        np.testing.assert_allclose(compiled[level], oracle, rtol=1e-4, atol=1e-12)
    assert acc.clipped_only().any()  # texels behind the clipped rows keep a lower bound only


def test_the_frame_culling_keeps_every_texel_in_view():
    """The accumulation visits only the chunks whose cone meets the frame's: every texel the frame's cone holds
    lies in one of them, at any orientation (and near the rim, whose chunks span the widest angles)."""
    camera = CameraIntrinsics.from_fov(640, 480, 62.0, k1=-0.05, k2=0.01)
    acc = ProbeAccumulator(256, camera, np.ones((480, 640)))
    rotations = Rotation.random(200, random_state=3).as_matrix()
    rotations[0] = Rotation.from_euler("y", 180, degrees=True).as_matrix()  # looking at -z: the rim
    for rotation in rotations:
        axis = np.ascontiguousarray(rotation.T[2])
        visited = np.zeros(len(acc.cones) * CHUNK, bool)
        visited.reshape(-1, CHUNK)[_chunks_in_view(acc.cones, axis, acc.min_cos)] = True
        seen = acc.directions @ axis >= acc.min_cos
        assert seen.any() and visited[:len(seen)][seen].all()
        assert visited.mean() < 2 * seen.mean()  # (and it culls: at most twice the texels in view)


def test_the_mean_of_gaussian_samples_clipped_at_zero_is_recovered():
    rng = np.random.default_rng(0)
    for mu in (0.3, 1.0, 2.0, 10.0):
        clipped_mean = np.maximum(rng.normal(mu, 1.0, 400_000), 0.0).mean()
        assert abs(clip_corrected(np.array([clipped_mean]), np.array([1.0]))[0] - mu) < 0.01 * max(mu, 1.0)


@pytest.mark.parametrize("level", [0.0015, 0.0025, 0.004])
def test_a_wall_at_the_read_noise_is_not_brightened_by_its_noise_clipped_at_zero(level):
    """A uniform dark room seen at ISO 3200 and the longest exposure with a signal a third of its noise to twice
    it (a dim room at the camera's limits). Its noise, clipped at code 0, made it 62, 27 and 10 % too bright;
    corrected, +1.8, -4.2 and -3.8 % (measured; what is left: the first code's threshold, which the clipped
    Gaussian does not model, and each sample's noise taken at its own code)."""
    n, camera = 32, CameraIntrinsics.from_fov(160, 120, 60.0)
    probe = (np.full((n, n, 3), level) * anglemap_disk_mask(n)[..., None]).astype(np.float32)
    sensor = SensorSettings()
    exposure_s, iso = 1 / 30, 3200.0
    scale = exposure_s * iso / sensor.base_iso * sensor.sensitivity
    with_noise = ProbeAccumulator(n, camera, np.ones((120, 160)), sensor=SensorNoise(sensor.full_well_e, sensor.read_noise_e))
    without = ProbeAccumulator(n, camera, np.ones((120, 160)))
    for k, rotation in enumerate(CaptureSweep().camera_orientation(np.linspace(0, 60, 60))):
        radiance = environment_view_reference(probe, camera, rotation)
        codes = expose(radiance, exposure_s, iso, sensor, TRUE_CURVE, pixel_normals(k, 120, 160), np.ones((120, 160)))
        for acc in (with_noise, without):
            acc.add(codes, ideal_response().linear / scale, rotation.as_matrix(), scale, 0, iso / sensor.base_iso)
    seen = with_noise.covered() & anglemap_disk_mask(n)
    biased, corrected = (acc.probe()[seen].mean() / level - 1 for acc in (without, with_noise))
    assert biased > 0.05 and abs(corrected) < min(0.05, biased / 2), (biased, corrected)


def smooth_environment(n):
    """A positive environment smooth at the scale of a texel (so that resampling it into frames and back
    is exact to well below 1 %), with a 20:1 range."""
    d = anglemap_directions(n)
    base = 1.0 + 0.6 * d[..., 0] + 0.3 * d[..., 1] ** 2 + 0.25 * np.sin(3.0 * d[..., 2])
    probe = np.stack([base, 0.8 * base + 0.2 * d[..., 1] ** 2, 1.2 * base], axis=-1) ** 2
    return (probe * anglemap_disk_mask(n)[..., None]).astype(np.float32)


def test_perfect_sensor_and_ideal_camera_reproduce_the_truth():
    """No noise, no vignetting, the true response, the true orientations: the covered texels are the
    truth within 1 % (8-bit quantisation averaged over the frames that saw each texel)."""
    probe = smooth_environment(64)
    camera = CameraIntrinsics.from_fov(320, 240, 60.0)
    acc = ProbeAccumulator(64, camera, np.ones((240, 320)))
    inside = anglemap_disk_mask(64)
    for rotation in CaptureSweep().camera_orientation(np.linspace(0, 60, 120)):
        radiance = environment_view_reference(probe, camera, rotation)
        scale = 0.18 / max(float(np.median(radiance.mean(axis=-1))), 1e-9)  # an exact auto-exposure
        acc.add(TRUE_CURVE.encode(radiance * scale), ideal_response().linear / scale, rotation.as_matrix())
    measured = acc.covered() & inside
    assert acc.coverage() > 0.95 and not acc.clipped_only().any()
    rel = np.abs(acc.probe()[measured] - probe[measured]) / probe[measured]
    assert rel.mean() < 0.01 and np.median(rel) < 0.005


LAMP_N = 128


def lamp_scene() -> tuple[np.ndarray, np.ndarray]:
    """A dim room with one small lamp 2000x brighter: (probe, lamp mask)."""
    d = anglemap_directions(LAMP_N)
    lamp = np.degrees(np.arccos(np.clip(d @ [0.0, 0.0, 1.0], -1, 1))) < 3.0
    room = 0.5 + 0.2 * d[..., 0] ** 2
    probe = np.where(lamp, 2000.0, room)[..., None] * [1.0, 0.9, 0.8] * anglemap_disk_mask(LAMP_N)[..., None]
    return probe.astype(np.float32), lamp


def swept_lamp(levels: int, bracket_ev: tuple[float, ...] = (0.0, -14.0), error_deg: float = 0.5) -> ProbeAccumulator:
    """The lamp scene swept with frames cycling through the bracket (0: a metered exposure, the lamp
    clipped), each taken with a random orientation error of error_deg RMS per axis, accumulated with
    the frames kept apart by exposure (levels = len(bracket_ev)) or not (levels=1)."""
    probe, _ = lamp_scene()
    camera = CameraIntrinsics.from_fov(160, 120, 60.0)
    acc = ProbeAccumulator(LAMP_N, camera, np.ones((120, 160)), levels=levels)
    rng = np.random.default_rng(3)
    for k, yaw in enumerate(np.linspace(-25, 25, 80)):
        truth = Rotation.from_euler("yx", [yaw, 10 * np.sin(k)], degrees=True)
        taken = truth * Rotation.from_rotvec(rng.normal(0, np.radians(error_deg), 3))
        index = k % len(bracket_ev)
        scale = 0.18 / 0.5 * 2.0 ** bracket_ev[index]
        frame = TRUE_CURVE.encode(environment_view_reference(probe, camera, truth) * scale)
        acc.add(frame, ideal_response().linear / scale, taken.as_matrix(), scale, min(index, levels - 1))
    return acc


def lamp_capture(levels: int) -> tuple[float, float]:
    """(captured over true energy of the lamp and the 3 texels around it, median relative error of
    the room) for the swept lamp."""
    probe, lamp = lamp_scene()
    acc = swept_lamp(levels)
    near = cv2.dilate(lamp.astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
    captured, luminance = acc.probe(), np.array([0.3, 0.6, 0.1])
    room_texels = acc.covered() & ~near & anglemap_disk_mask(LAMP_N)
    return (float((captured[near] @ luminance).sum() / (probe[near] @ luminance).sum()),
            float(np.median(np.abs(captured[room_texels] - probe[room_texels]) / probe[room_texels])))


def test_a_source_clipped_at_every_exposure_is_reported():
    """Without short exposures the lamp is clipped in every frame: the capture keeps a lower bound,
    says how much of the source that is, and warns that the exposure range cannot hold it."""
    from arsim.capture.pipeline import CaptureResult
    from arsim.evaluate.capture_report import brightest_warning, capture_metrics

    probe, _ = lamp_scene()
    acc = swept_lamp(levels=1, bracket_ev=(0.0,), error_deg=0.0)
    still = Rotation.identity(80)
    result = CaptureResult(acc, ideal_response(), np.arange(80) / 30, still, still, still, still, np.zeros(80, bool), 1.0, 1.0,
                           (np.zeros(3), np.zeros(3)))
    metrics, _ = capture_metrics(result, probe, {"median_pct": 0.0, "max_pct": 0.0})
    assert metrics["brightest_source_clipped_pct"] > 10 and metrics["brightest_source_ratio"] < 0.1
    assert "lower bound" in brightest_warning(metrics)


def test_frames_kept_apart_by_exposure_keep_a_misregistered_lamp_whole():
    """Merged as one level, every metered frame that a small orientation error puts beside the lamp
    outweighs the short exposures that saw the lamp there, and the lamp shrinks; merged by exposure
    level, each texel takes the level that mostly saw it unclipped, and the lamp keeps its energy."""
    one_level, room_one = lamp_capture(levels=1)
    by_level, room_by_level = lamp_capture(levels=2)
    assert abs(by_level - 1.0) < 0.05 and one_level < 0.9
    assert room_by_level < 0.02 and room_one < 0.02


@pytest.fixture(scope="module")
def detailed_probe():
    return to_layout(read_hdr(ENVMAPS[1]), "anglemap", 512)


@pytest.mark.parametrize("offset_deg", [[0.0, 1.5, 0.0], [0.8, -0.6, 0.4]])
def test_alignment_finds_a_known_rotation(detailed_probe, offset_deg):
    camera = CameraIntrinsics.from_fov(640, 480, 60.0)
    truth = Rotation.from_euler("yx", [40, -10], degrees=True)
    radiance = environment_view_reference(detailed_probe, camera, truth)
    scale = 0.18 / float(np.median(radiance.mean(axis=-1)))
    frame = TRUE_CURVE.encode(radiance * scale)
    predicted = truth * Rotation.from_euler("xyz", offset_deg, degrees=True)
    aligner = Aligner(camera, np.ones((480, 640)), ideal_response())
    found = aligner.align(frame, known_probe(detailed_probe, camera), predicted.as_matrix(), scale)
    assert found.rotation is not None and found.inliers >= 20
    error = np.degrees(((predicted * found.rotation).inv() * truth).magnitude())
    assert error < 0.1


def test_a_featureless_frame_changes_nothing():
    camera = CameraIntrinsics.from_fov(640, 480, 60.0)
    probe = np.full((128, 128, 3), 0.5, np.float32) * anglemap_disk_mask(128)[..., None]
    frame = np.full((480, 640, 3), 128, np.uint8)
    aligner = Aligner(camera, np.ones((480, 640)), ideal_response())
    found = aligner.align(frame, known_probe(probe, camera), Rotation.identity().as_matrix(), 1.0)
    assert found.rotation is None


def test_robertson_recovers_the_response_from_a_burst(detailed_probe):
    camera = CameraIntrinsics.from_fov(320, 240, 60.0)
    view = Rotation.from_euler("y", 100, degrees=True)
    radiance = environment_view_reference(detailed_probe, camera, view)
    base = 0.18 / float(np.median(radiance.mean(axis=-1)))
    products = base * 2.0 ** np.arange(-3, 4)
    frames = [TRUE_CURVE.encode(radiance * p) for p in products]
    error = response_error(calibrate_response(frames, products), TRUE_CURVE.decode(np.arange(256)))
    assert error["median_pct"] < 3 and error["max_pct"] < 10


@pytest.fixture(scope="module")
def short_recording(tmp_path_factory):
    root = tmp_path_factory.mktemp("capture")
    (root / "short.toml").write_text(SHORT.format(seed=0))  # the recording tests' short sweep (and AR path)
    r = arsim("record", root / "short.toml", "-o", root / "rec")
    assert r.returncode == 0, r.stderr
    return root / "rec"


def test_capture_of_a_short_recording_writes_every_output(short_recording, tmp_path):
    import json

    r = arsim("capture", short_recording, "-o", tmp_path / "out", "--size", "64")
    assert r.returncode == 0, r.stderr
    for name in ("env.exr", "truth.exr", "coverage.png", "drift.png", "probe_vs_truth.png", "metrics.json"):
        assert (tmp_path / "out" / name).exists(), name
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    for key in ("coverage_pct", "orientation_rms_deg_corrected", "orientation_rms_deg_uncorrected",
                "irradiance_mean_err_pct", "frames_per_second"):
        assert np.isfinite(metrics[key]), key
    assert 0 < metrics["coverage_pct"] <= 100


def test_the_capture_reports_progress_through_its_refinement(short_recording):
    """The refinement (keyframe features, pairs, direct alignments: half of the default capture's time) reports
    as it goes instead of holding the progress still: the fraction never falls, passes through the
    refinement's share several times and ends at 1."""
    from arsim.capture.pipeline import ONLINE_SHARE, REFINE_SHARE, CaptureSettings, capture
    from arsim.sensors.recording import load_recording

    fractions = []
    result = capture(load_recording(short_recording), CaptureSettings(size=64), lambda f, coverage: fractions.append(f))
    assert result.refinement is not None
    assert all(b >= a for a, b in zip(fractions, fractions[1:])), fractions
    assert len([f for f in fractions if ONLINE_SHARE < f < ONLINE_SHARE + REFINE_SHARE]) >= 3, fractions
    assert fractions[-1] == 1.0


def _no_frames(rec):
    for png in (rec / "frames").glob("*.png"):
        png.unlink()
    (rec / "frames.csv").write_text("t_ns,exposure_ns,iso,file\n")


def _no_burst(rec):
    (rec / "burst.csv").write_text("exposure_ns,iso,file\n")


def _saturated(rec):
    import cv2

    for png in (rec / "frames").glob("*.png"):
        cv2.imwrite(str(png), np.full((72, 96, 3), 255, np.uint8))


def _one_exposure_burst(rec):
    lines = (rec / "burst.csv").read_text().splitlines()
    first = lines[1].split(",")
    (rec / "burst.csv").write_text("\n".join([lines[0]] + [",".join(first[:2] + [row.split(",")[2]]) for row in lines[1:]]) + "\n")


def _never_overlapping(rec):
    """Frames kept only where the true view has turned 70 degrees from the last kept one."""
    from arsim.sensors.frames import frame_camera_orientations
    from arsim.sensors.recording import load_recording

    axes = frame_camera_orientations(load_recording(rec)).apply([0.0, 0.0, 1.0])
    keep = [0]
    for k in range(1, len(axes)):
        if np.degrees(np.arccos(np.clip(axes[k] @ axes[keep[-1]], -1, 1))) >= 70:
            keep.append(k)
    assert len(keep) >= 3
    lines = (rec / "frames.csv").read_text().splitlines()
    (rec / "frames.csv").write_text("\n".join([lines[0]] + [lines[1 + k] for k in keep]) + "\n")
    for k, line in enumerate(lines[1:]):
        if k not in keep:
            (rec / line.split(",")[-1]).unlink()


@pytest.mark.parametrize("damage, message", [(_no_frames, "no frames"), (_no_burst, "no response burst"),
                                             (_saturated, "saturated"), (_one_exposure_burst, "same exposure"),
                                             (_never_overlapping, "no two consecutive frames overlap")])
def test_unusable_recordings_are_refused(short_recording, tmp_path, damage, message):
    import shutil

    rec = shutil.copytree(short_recording, tmp_path / "rec")
    damage(rec)
    r = arsim("capture", rec, "-o", tmp_path / "out")
    assert_one_line_error(r, message)
    assert not (tmp_path / "out" / "env.exr").exists()


def _capture_metrics(scenario, out):
    """`arsim capture SCENARIO -o OUT` (recorded first): its metrics.json and the process."""
    import json

    r = arsim("capture", scenario, "-o", out)
    assert r.returncode == 0, r.stderr
    return json.loads((out / "metrics.json").read_text()), r


def test_a_scene_without_features_falls_back_to_the_imu_and_says_so(tmp_path):
    """A sky-like gradient with nothing to match: no alignment, no keyframe pair; the orientations are the
    IMU's, and metrics.json says so."""

    from arsim.core.conventions import equirect_directions
    from arsim.core.hdr_io import write_exr

    up = equirect_directions(64)[..., 1]
    write_exr(tmp_path / "flat.exr", np.repeat((0.3 + 0.2 * up)[..., None], 3, axis=-1).astype(np.float32))
    (tmp_path / "flat.toml").write_text(f"""
[environment]
map = "{(tmp_path / 'flat.exr').as_posix()}"
probe_size = 64
[capture]
duration_s = 4.0
capture_size = 64
[device.camera]
width = 160
height = 120
fps = 10.0
[ar]
enabled = false
""")
    metrics, r = _capture_metrics(tmp_path / "flat.toml", tmp_path / "out")
    assert metrics["alignments_succeeded"] == 0 and metrics["loop_closures"] == 0 and metrics["refined"]
    assert any("the IMU's alone" in w for w in metrics["warnings"]) and "the IMU's alone" in r.stderr
    # nothing measured the bias: the estimate is its prior, 0 with the device's figures (turn-on bias and
    # instability), widened by its random walk over the sweep
    assert metrics["gyro_bias_dps_online"] == [0.0, 0.0, 0.0]
    prior, wander = np.radians(0.05) + 5e-5, 2e-5**2 + 2 * 5e-5**2 / 100.0
    duration = (metrics["frames"] - 1) / 10.0
    assert np.allclose(metrics["gyro_bias_sigma_dps_online"], np.degrees(np.sqrt(prior**2 + wander * duration)), rtol=1e-3)
    assert abs(metrics["orientation_rms_deg_corrected"] - metrics["orientation_rms_deg_uncorrected"]) < 0.05


def test_the_refinement_removes_an_injected_gyroscope_drift(tmp_path):
    """A 20 s sweep of the interior with a gyroscope whose turn-on bias is 1 degree/s (a drift the truth
    knows): the refined orientations against the IMU's. Measured: 0.080 degrees RMS refined, 2.64 uncorrected
    (the online pass 3.3: against a 128² probe its alignments are 2 degrees off; into 512², 0.30). The last 8 s
    look at the bare ceiling, where no keyframe pair matches by features: aligned directly (159 pairs), they
    hold within 0.11 degrees; with the calibrated gyroscope alone there, 0.18 RMS (0.32-0.38 at the end)."""

    (tmp_path / "drift.toml").write_text("""
[run]
seed = 3
[environment]
map = "envmaps/interior.exr"
probe_size = 256
[capture]
duration_s = 20.0
capture_size = 128
[device.gyroscope]
turn_on_bias = 0.0175
[ar]
enabled = false
""")
    metrics, _ = _capture_metrics(tmp_path / "drift.toml", tmp_path / "out")
    assert metrics["refined"] and metrics["loop_closures"] > 100 and metrics["direct_pairs"] > 50
    assert metrics["orientation_rms_deg_corrected"] < 0.1
    assert metrics["orientation_rms_deg_uncorrected"] > 10 * metrics["orientation_rms_deg_corrected"]


def test_the_probe_is_its_numpy_form_texel_for_texel():
    """probe()'s compiled correction of the noise clipped at 0 gives what its NumPy form does, on an
    accumulator's maps with every case: unseen, never weighted, mostly clipped, no spread, far above the
    noise and near it."""
    rng = np.random.default_rng(3)
    camera = CameraIntrinsics.from_fov(64, 48, 60.0)
    acc = ProbeAccumulator(32, camera, np.ones((48, 64)), levels=2, sensor=SensorNoise(6000.0, 2.0))
    shape = acc.radiance.shape
    acc.radiance = np.where(rng.random(shape) < 0.1, -1.0, rng.gamma(1.0, 0.05, shape))
    acc.weights[:] = np.where(rng.random((2, *shape)) < 0.15, 0.0, rng.gamma(2.0, 1.0, (2, *shape)))
    acc.sums[:] = acc.weights * rng.gamma(1.0, 0.05, (2, *shape))
    acc.variances[:] = np.where(rng.random((2, *shape)) < 0.1, 0.0, acc.weights * rng.gamma(1.0, 0.02, (2, *shape)) ** 2)
    acc.unclipped_votes[:], acc.clipped_votes[:] = rng.random((2, 2, *shape))
    radiance = np.maximum(acc.radiance, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        mean = acc.sums[0] / acc.weights[0]
        sigma = np.sqrt(acc.variances[0] / acc.weights[0])
    longest = (acc.weights[0] > 0) & (acc.unclipped_votes[0] >= acc.clipped_votes[0]) & (sigma > 0)
    bias = mean - clip_corrected(np.where(longest, mean, 0.0), np.where(longest, sigma, 1.0))
    expected = np.where(longest & (radiance > 0), np.maximum(radiance - bias, 0.0), radiance).astype(np.float32)
    ratio = np.where(longest, mean / np.where(longest, sigma, 1.0), np.inf)
    assert (longest & (ratio < 8)).sum() > 100 and (longest & (ratio > 8)).sum() > 100 and (~longest).sum() > 100
    np.testing.assert_array_equal(acc.probe(), expected)
