"""Recordings without a ground truth (a real phone's, a data set's): no groundtruth.csv, and without the
scenario in meta.json too. `capture`, `render`, `run` and `info` work on them; what needs the truth is left
out, saying why (metrics.json's "truth", the report), never NaN-filled. And the capture's orientations as the
SLAM community measures them (evo's APE and RPE) and exchanges them (TUM trajectory files)."""

import json
import shutil

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from arsim.sensors.frames import NO_GROUNDTRUTH, NO_SCENARIO, recording_scenario, truth_absent
from arsim.sensors.recording import load_recording
from tests.conftest import ENVMAPS
from tests.test_cli import arsim

# Small and short: a 1 s sweep of 320 x 240 frames at 10 frames/s, a 3 s AR path. The camera and capture
# settings the default scenario has too (the recording without its scenario is read with the default's).
SMALL = """
[run]
name = "small"
seed = 3
[environment]
map = "{env}"
probe_size = 128
[capture]
duration_s = 1.0
capture_size = 128
[device.camera]
width = 320
height = 240
fps = 10.0
[ar]
duration_s = 3.0
near_m = 0.3
far_m = 0.6
[render]
map_size = 32
[[render.objects]]
kind = "sphere"
size_m = 0.05
exponent = 80.0
"""


def _without(src, dst, scenario: bool):
    """A copy of the recording src without groundtruth.csv (sweep and AR path), and without meta.json's
    scenario_toml where `scenario` is false."""
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("plots"))
    for folder in (dst, dst / "ar"):
        (folder / "groundtruth.csv").unlink()
        if not scenario:
            meta = json.loads((folder / "meta.json").read_text())
            del meta["scenario_toml"]
            (folder / "meta.json").write_text(json.dumps(meta, indent=2))
    return dst


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    root = tmp_path_factory.mktemp("no_truth")
    (root / "s.toml").write_text(SMALL.format(env=ENVMAPS[1].as_posix()))
    r = arsim("record", root / "s.toml", "-o", root / "rec")
    assert r.returncode == 0, r.stderr
    return {"scenario": root / "s.toml", "full": root / "rec",
            "no_groundtruth": _without(root / "rec", root / "no_groundtruth", scenario=True),
            "nothing": _without(root / "rec", root / "nothing", scenario=False)}


def _ok(result):
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    return result


def test_a_recording_without_groundtruth_loads_and_says_what_it_lacks(recordings):
    rec = load_recording(recordings["nothing"])
    assert rec.groundtruth is None and "scenario_toml" not in rec.meta
    assert truth_absent(rec) == {"groundtruth": NO_GROUNDTRUTH, "scenario": NO_SCENARIO}
    assert truth_absent(load_recording(recordings["no_groundtruth"])) == {"groundtruth": NO_GROUNDTRUTH}
    assert truth_absent(load_recording(recordings["full"])) == {}
    # without its scenario, the default's sensor settings describe the recording
    assert recording_scenario(rec).run.name == "default"
    assert recording_scenario(rec).capture.bracket_ev == (0.0,)  # (a camera's own stream: every frame metered)
    for name in ("no_groundtruth", "nothing"):
        out = _ok(arsim("info", recordings[name])).stdout
        assert "no groundtruth.csv" in out
        assert ("no scenario_toml" in out) == (name == "nothing")


@pytest.mark.parametrize("name", ["no_groundtruth", "nothing"])
def test_capture_leaves_out_what_needs_the_truth_and_says_why(recordings, tmp_path, name):
    from evo.tools.file_interface import read_tum_trajectory_file

    out = tmp_path / "capture"
    printed = _ok(arsim("capture", recordings[name], "-o", out, "--size", "64")).stdout
    assert "not measured (no ground truth)" in printed
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["truth"]["groundtruth"] == NO_GROUNDTRUTH
    assert not any(k.startswith(("orientation_", "ape_", "rpe_")) for k in metrics)
    assert metrics["coverage_pct"] > 0 and metrics["frames"] == 11
    # the environment is known from the scenario where meta.json keeps it
    assert ("irradiance_mean_err_pct" in metrics) == (name == "no_groundtruth")
    assert ("scenario" in metrics["truth"]) == (name == "nothing")
    assert (out / "truth.exr").is_file() == (name == "no_groundtruth")
    assert (out / ("probe_vs_truth.png" if name == "no_groundtruth" else "probe.png")).is_file()
    assert not any(isinstance(v, float) and not np.isfinite(v) for v in metrics.values())
    # the estimated and fused orientations as TUM files; no truth file
    assert not (out / "trajectory_truth.tum").exists()
    for stream in ("capture", "fused"):
        trajectory = read_tum_trajectory_file(str(out / f"trajectory_{stream}.tum"))
        assert trajectory.num_poses == 11 and not trajectory.positions_xyz.any()


@pytest.mark.parametrize("name", ["no_groundtruth", "nothing"])
def test_render_replays_a_recording_without_the_truth(recordings, tmp_path, name):
    out = tmp_path / "session"
    printed = _ok(arsim("render", recordings["scenario"], "--recording", recordings[name], "-o", out)).stdout
    assert "tracking not measured (no ground truth)" in printed
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["truth"]["groundtruth"] == NO_GROUNDTRUTH
    assert not any(k.startswith("tracking_") for k in metrics)
    assert metrics["frames_total"] == 31 and (out / "session.mp4").is_file()
    scored = name == "no_groundtruth"
    assert ("flip_mean" in metrics) == scored and ("scenario" in metrics["truth"]) == (not scored)
    if scored:
        assert np.isfinite(metrics["flip_mean"])


@pytest.fixture(scope="module")
def runs(recordings, tmp_path_factory):
    root = tmp_path_factory.mktemp("no_truth_runs")
    for name in ("no_groundtruth", "nothing"):
        _ok(arsim("run", recordings["scenario"], "--recording", recordings[name], "-o", root / name))
    return root


@pytest.mark.parametrize("name", ["no_groundtruth", "nothing"])
def test_run_writes_probe_maps_frames_and_a_report_that_says_what_it_leaves_out(runs, name):
    out = runs / name
    for path in ("capture/env.exr", "capture/trajectory_capture.tum", "maps/fast/irradiance.exr", "session.mp4",
                 "estimates/platforms/capture_arcore.json", "estimates/platforms/single_arcore.json", "report/index.html"):
        assert (out / path).is_file(), path
    assert list((out / "frames").glob("*.png"))
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["truth"]["groundtruth"] == NO_GROUNDTRUTH
    assert not any(k.startswith("tracking_") for k in metrics["session"])
    assert not any(k.startswith("orientation_") for k in metrics["capture"])
    report = (out / "report" / "index.html").read_text()
    assert report.count("Left out:") >= 4 and "the tracking&#x27;s errors" in report
    assert "no groundtruth.csv" in report
    if name == "nothing":
        assert metrics["truth"]["scenario"] == NO_SCENARIO and metrics["estimates"] == {}
        assert all("per_exponent" not in m for m in metrics["maps"].values())
        assert "flip_mean" not in metrics["session"] and "probe_vs_truth" not in report
        assert "the maps&#x27; errors" in report and "the estimates&#x27; scores" in report
        assert json.loads((out / "estimates" / "scores.json").read_text()) == {"truth": NO_SCENARIO}
        assert not (out / "estimates" / "platforms" / "truth_arcore.json").exists()
    else:
        assert "scenario" not in metrics["truth"] and np.isfinite(metrics["session"]["flip_mean"])
        assert all(m["per_exponent"] for m in metrics["maps"].values())
    printed = _ok(arsim("info", out)).stdout
    assert "no groundtruth.csv" in printed


def test_apes_rotation_rmse_is_arsims_orientation_rms_and_the_tum_files_read_back(recordings, tmp_path):
    """On a recording with its truth: evo's APE of the rotation (RMSE) is the capture's own orientation error
    RMS, computed apart; the TUM files read back through evo as the orientations written."""
    from evo.core import metrics as evo_metrics
    from evo.tools.file_interface import read_tum_trajectory_file

    out = tmp_path / "capture"
    _ok(arsim("capture", recordings["full"], "-o", out, "--size", "64"))
    m = json.loads((out / "metrics.json").read_text())
    assert "truth" not in m
    assert abs(m["ape_rot_rmse_deg_corrected"] - m["orientation_rms_deg_corrected"]) < 1e-6
    assert abs(m["ape_rot_rmse_deg_uncorrected"] - m["orientation_rms_deg_uncorrected"]) < 1e-6
    assert abs(m["ape_rot_max_deg_corrected"] - m["orientation_max_deg_corrected"]) < 1e-6
    assert m["rpe_delta_frames"] == 10 and m["rpe_rot_rmse_deg_uncorrected"] > 0
    truth = read_tum_trajectory_file(str(out / "trajectory_truth.tum"))
    estimate = read_tum_trajectory_file(str(out / "trajectory_capture.tum"))
    # the files hold the frame times in seconds and the orientations arsim measured (independently of evo:
    # SciPy's angles between the quaternions read back as text)
    rec = load_recording(recordings["full"])
    assert np.allclose(truth.timestamps, [f["t_ns"] / 1e9 for f in rec.frames], atol=1e-6)
    lines = [np.array(line.split(), dtype=np.float64) for line in (out / "trajectory_truth.tum").read_text().splitlines()]
    other = [np.array(line.split(), dtype=np.float64) for line in (out / "trajectory_capture.tum").read_text().splitlines()]
    angles = np.degrees((Rotation.from_quat([r[4:] for r in lines]).inv() * Rotation.from_quat([r[4:] for r in other])).magnitude())
    assert abs(np.sqrt(np.mean(angles**2)) - m["orientation_rms_deg_corrected"]) < 1e-6
    ape = evo_metrics.APE(evo_metrics.PoseRelation.rotation_angle_deg)
    ape.process_data((truth, estimate))
    assert abs(ape.get_statistic(evo_metrics.StatisticsType.rmse) - m["ape_rot_rmse_deg_corrected"]) < 1e-6


def test_a_recording_with_nothing_to_linearise_its_frames_is_refused_in_one_line(recordings, tmp_path):
    from tests.test_cli import assert_one_line_error

    rec = tmp_path / "rec"
    shutil.copytree(recordings["nothing"], rec, ignore=shutil.ignore_patterns("ar", "burst"))
    (rec / "burst.csv").write_text("exposure_ns,iso,file\n")
    assert_one_line_error(arsim("capture", rec, "-o", tmp_path / "out"), str(rec), "no response burst",
                          "no photometric calibration")
    assert not (tmp_path / "out").exists()


def test_estimate_without_the_true_environment_makes_the_estimates_and_scores_none(recordings, tmp_path):
    out = tmp_path / "estimates"
    printed = _ok(arsim("estimate", recordings["nothing"], "-o", out)).stdout
    assert "no scores: the truth is absent" in printed
    lines = [json.loads(line) for line in (out / "estimates.jsonl").read_text().splitlines()]
    assert len(lines) == 11 and all("truth" not in line and "single" in line for line in lines) and "capture" in lines[-1]
    assert json.loads((out / "scores.json").read_text()) == {"truth": NO_SCENARIO}
    assert (out / "spheres.png").is_file() and not (out / "scores.png").exists()
    assert sorted(p.name for p in (out / "platforms").glob("*_arcore.json")) == ["capture_arcore.json", "single_arcore.json"]
