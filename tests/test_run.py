"""`arsim run` end to end on a small scenario (the run directory, manifest, report, replay of a recording
giving byte-identical frames), visual regression (`arsim diff`, --baseline, the arsim_baseline fixture),
and bad input refused in one line."""

import json
from pathlib import Path

import numpy as np
import pytest

from arsim.core.files import OUTPUT_MARK
from arsim.core.png import png_bytes
from arsim.evaluate.diff import compare_images, run_diff
from arsim.sensors.recording import NOT_KEPT
from arsim.testing import assert_frames_match, update_baseline
from tests.conftest import ENVMAPS
from tests.test_cli import arsim, assert_one_line_error

SMALL = """
[run]
name = "small"
seed = 7
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
duration_s = 4.0
near_m = 0.3
far_m = 0.6
[[ar.look_away]]
start_s = 1.5
end_s = 2.5
[render]
map_size = 32
methods = ["mipmap"]
[[render.objects]]
kind = "torus"
[[render.objects]]
kind = "sphere"
position_m = [0.17, 0.0]
size_m = 0.04
exponent = {exponent}
"""


def _tree(root) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*") if p.is_file())


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A run (a; its recording's frame images not kept), its recording made again from its scenario.toml as its
    manifest says (rec), the same scenario replayed from rec, and a run with the sphere's exponent changed
    (changed). The folder a held a run of the changed scenario first (its frames kept: first.json says what it
    held), which the run a replaced, reusing its recording, capture and estimates from the cache."""
    root = tmp_path_factory.mktemp("runs")
    (root / "s.toml").write_text(SMALL.format(env=ENVMAPS[1].as_posix(), exponent=80.0))
    (root / "t.toml").write_text(SMALL.format(env=ENVMAPS[1].as_posix(), exponent=10.0))
    cache = root / "cache"
    results = {"first": arsim("run", root / "t.toml", "-o", root / "a", "--keep-recording", "--cache", cache)}
    assert results["first"].returncode == 0, results["first"].stderr
    (root / "first.json").write_text(json.dumps({"files": _tree(root / "a"), "stdout": results["first"].stdout,
                                                 "manifest": json.loads((root / "a" / "manifest.json").read_text())}))
    results["changed"] = arsim("run", root / "t.toml", "-o", root / "changed", "--recording", root / "a" / "recording")
    results["a"] = arsim("run", root / "s.toml", "-o", root / "a", "--cache", cache)
    results["record"] = arsim("record", root / "a" / "scenario.toml", "-o", root / "rec")
    results["replay"] = arsim("run", root / "s.toml", "-o", root / "replay", "--recording", root / "rec")
    for name, r in results.items():
        assert r.returncode == 0, (name, r.stderr)
    (root / "a.stdout").write_text(results["a"].stdout)
    return root


def test_run_writes_the_run_directory_manifest_and_report(runs):
    out = runs / "a"
    for path in ("manifest.json", "metrics.json", "scenario.toml", "recording/frames.csv", "capture/env.exr",
                 "capture/drift.png", "maps/fast/irradiance.exr", "maps/fast/bake.json", "maps/mipmap/reflection_s80.exr",
                 "session.mp4", "profile/profile.md", "profile/trace.json", "profile/timeline.png", "report/index.html"):
        assert (out / path).is_file(), path
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["seed"] == 7 and manifest["scenario"]["name"] == "small"
    assert set(manifest["seconds_per_stage"]) == {"recording", "capture", "estimates", "maps", "session", "report"}
    # the CPU time beside the wall time, per stage: a computed stage does seconds of work here, a reused one may
    # take less than the 10 ms the figures are rounded to
    cpu = manifest["cpu_seconds_per_stage"]
    assert set(cpu) == set(manifest["seconds_per_stage"])
    assert all(manifest["stages"][name]["cpu_seconds"] == v for name, v in cpu.items())
    computed = [name for name, st in manifest["stages"].items() if st["status"] == "computed"]
    assert computed and all(cpu[name] > 0 for name in computed) and all(v >= 0 for v in cpu.values())
    # The truth frame and its FLIP on every 4th frame (the default flip_every) and on the saved frames.
    session = json.loads((out / "metrics.json").read_text())["session"]
    saved = {int(p.stem) for p in (out / "frames").glob("*.png")}
    measured = [(n, k) for n, (k, f) in enumerate(zip(session["frames_rendered"], session["flip_per_frame"])) if f is not None]
    assert measured and session["flip_frames"] == len(measured)
    assert all(n % 4 == 0 or k in saved for n, k in measured)
    roles = {f["path"]: f["role"] for f in manifest["files"]}
    assert roles["capture/env.exr"].startswith("the captured") and roles["session.mp4"].startswith("the AR session")
    session = manifest["metrics"]["session"]
    assert session["frames_lost"] > 0 and session["frames_total"] == 41  # 4 s at 10 frames/s; the look-away
    assert set(manifest["metrics"]["maps"]) == {"fast", "mipmap"}
    page = (out / "report" / "index.html").read_text()
    for section in ("Summary", "Scenario", "Captured probe and the truth", "Light estimates as phones report them", "Maps",
                    "AR frames", "Every figure", "IMU drift", "Tracking", "Frame time"):
        assert section in page, section
    assert page.count("data:image/png;base64,") >= 8  # self-contained: every image embedded
    assert "the tag was\nlost in" in page


def test_run_lights_the_objects_with_each_light_estimate_beside_the_truth_frame(runs):
    """The light estimates' stage: estimates.jsonl and scores over the sweep, and at every frame shown where
    the tag was found, the objects lit by the truth's, the capture's and the single frame's estimates scored
    against the truth frame (FLIP over the objects), drawn beside it."""
    out = runs / "a"
    for path in ("estimates/estimates.jsonl", "estimates/scores.json", "estimates/scores.png", "estimates/spheres.png",
                 "estimates/platforms/capture_arcore.json"):
        assert (out / path).is_file(), path
    estimates = json.loads((out / "metrics.json").read_text())["estimates"]
    shown = sorted(int(p.stem) for p in (out / "estimates" / "frames").glob("*.png"))
    assert shown and shown == sorted(int(k) for k in estimates["capture"]["ar_flip_per_frame"])
    assert set(shown) <= {int(p.stem) for p in (out / "frames").glob("*.png")}
    for name in ("truth", "capture", "single"):
        flips = list(estimates[name]["ar_flip_per_frame"].values())
        assert all(0.0 < f < 1.0 for f in flips) and estimates[name]["ar_flip_mean"] == pytest.approx(np.mean(flips))
    # The truth's own estimate lights them near the truth frame (what its shapes lose: 0.03 here); one frame,
    # seeing a sixth of the sphere, far from it (0.31). (The capture's estimate needs a longer sweep than this
    # one second: the README's runs measure it.)
    assert estimates["truth"]["ar_flip_mean"] < 0.5 * estimates["single"]["ar_flip_mean"]


def test_a_recording_replayed_gives_byte_identical_frames(runs):
    frames = sorted(p.name for p in (runs / "a" / "frames").glob("*.png"))
    assert len(frames) == 4
    for name in frames:
        assert (runs / "a" / "frames" / name).read_bytes() == (runs / "replay" / "frames" / name).read_bytes(), name


def _json_differences(x, y, path: str = "") -> set[str]:
    """The keys (dotted, list indices as []) where two JSON values differ."""
    if isinstance(x, dict) and isinstance(y, dict):
        return set().union(*(_json_differences(x.get(k), y.get(k), f"{path}.{k}") for k in set(x) | set(y)))
    if isinstance(x, list) and isinstance(y, list) and len(x) == len(y):
        return set().union(set(), *(_json_differences(u, v, f"{path}[]") for u, v in zip(x, y)))
    return set() if x == y else {path}


def test_the_same_seed_gives_byte_identical_files_but_for_the_timed_ones(runs):
    # a run (recording made by it) against a replay of a recording made apart with the same seed:
    # only the files that carry measured times differ, and in those only the times (and sizes of files)
    import fnmatch
    import re

    from arsim.run.pipeline import TIMED_FILES

    def files(root):
        return {p.relative_to(root).as_posix(): p for p in root.rglob("*") if p.is_file()}

    # (the run's recording lacks its frame images and says so: the next test checks them against rec's)
    kept = {k: v for k, v in files(runs / "a" / "recording").items() if not k.endswith(NOT_KEPT)}
    pairs = [(kept, files(runs / "rec"))]
    a, replay = files(runs / "a"), files(runs / "replay")
    pairs.append(({k: v for k, v in a.items() if not k.startswith("recording/")}, replay))
    assert set(pairs[1][0]) == set(replay)
    timed = re.compile(r"seconds|_ms|per_second|\.(cpu|gl)\.|\.dur$|\.ts$|misses|within_budget|\.bytes$")
    differing = []
    for first, second in pairs:
        assert set(first) <= set(second)  # (`arsim record` also writes plots/, which a run's recording lacks)
        for name in sorted(first):
            if first[name].read_bytes() == second[name].read_bytes():
                continue
            differing.append(name)
            assert any(fnmatch.fnmatch(name, pattern) for pattern in TIMED_FILES), name
            if name.endswith(".json"):
                x, y = json.loads(first[name].read_text()), json.loads(second[name].read_text())
                if name == "manifest.json":  # a replay's manifest names its recording, which lies outside it
                    for m in (x, y):  # (and its stages: no recording, the capture keyed by that recording's content;
                        # a's took stages from a cache, the replay used none)
                        m["files"] = [f for f in m["files"] if not f["path"].startswith("recording")]
                        for key in ("recording", "stages", "cache", "recording_frames", "disk"):
                            m.pop(key)
                keys = _json_differences(x, y)
                assert keys and all(timed.search(k) for k in keys), (name, sorted(k for k in keys if not timed.search(k)))
    assert "frames/000000.png" not in differing and "capture/env.exr" not in differing and len(a) > 50


def _frames_differing(stored: Path, made: Path, images: dict[str, str]) -> dict:
    """Which of a recording's frames differ between the cache entry's copy (stored) and one made again, with the
    pixels that differ in each once decoded (0: the same image in other bytes)."""
    from arsim.core.png import read_frame
    from arsim.sensors.recording import recording_images

    kept = recording_images(stored)
    return {rel: int((read_frame(stored / rel) != read_frame(made / rel)).any(axis=-1).sum())
            for rel in sorted(images) if kept.get(rel) != images[rel] and (stored / rel).is_file()}


def test_the_recordings_frames_are_left_out_and_made_again_byte_identical_from_the_scenario(runs):
    """A run keeps its recording's small files, not its frame images; its manifest counts them and gives their
    digest, which `arsim record RUN/scenario.toml` (what the manifest and the run's last line say to run) matches."""
    from arsim.sensors.recording import images_digest, recording_image_paths, recording_images

    out, rec = runs / "a", runs / "rec"
    manifest = json.loads((out / "manifest.json").read_text())
    frames = manifest["recording_frames"]
    images = recording_images(rec)
    assert len(images) == 11 + 13 + 41  # the sweep's 1 s at 10 frames/s, the burst, the AR path's 4 s
    assert frames["kept"] is False and frames["files"] == len(images)
    assert frames["sha256"] == images_digest(images), _frames_differing(Path(frames["cache_entry"] or out), rec, images)
    assert frames["bytes"] == sum((rec / rel).stat().st_size for rel in images)
    assert not any(p.suffix == ".png" and p.parent.name in ("frames", "burst") for p in (out / "recording").rglob("*"))
    assert all(not (out / "recording" / rel).exists() for rel in recording_image_paths(rec))
    for segment, count in (("", 11 + 13), ("ar", 41)):
        note = json.loads((out / "recording" / segment / NOT_KEPT).read_text())
        assert note["files"] == count and note["recording_key"] == manifest["stages"]["recording"]["key"]
    # the frames are still in the cache entry the run took its recording from (until the cache drops it)
    entry = Path(frames["cache_entry"])
    assert entry.parent.parent == Path(manifest["stages"]["recording"]["from"]) and (entry / "ar" / "frames").is_dir()
    # the disk the run takes: every file of the folder (but the mark of arsim's output), the manifest included
    on_disk = [p for p in out.rglob("*") if p.is_file() and p.name != OUTPUT_MARK]
    assert manifest["disk"] == {"files": len(on_disk), "bytes": sum(p.stat().st_size for p in on_disk)}
    last = (runs / "a.stdout").read_text().splitlines()[-1]
    assert last.startswith(f"run: {manifest['disk']['bytes'] / 1e6:.1f} MB in {len(on_disk)} files (recording frames not kept")
    assert f"arsim record {out / 'scenario.toml'} -o rec" in last
    info = arsim("info", out)
    assert info.returncode == 0 and "recording frames not kept" in info.stdout, info.stdout + info.stderr
    assert f"or copy them from the run cache's {entry})" in info.stdout


def test_a_run_kept_its_frames_when_asked_and_was_replaced_whole_by_the_next_run_into_its_folder(runs):
    first = json.loads((runs / "first.json").read_text())
    frames = first["manifest"]["recording_frames"]
    assert frames["kept"] is True and frames["files"] == 11 + 13 + 41
    assert "recording/ar/frames/000000.png" in first["files"] and "recording/burst/00.png" in first["files"]
    assert "recording frames not kept" not in first["stdout"].splitlines()[-1]
    # the first run (exponent 10) wrote a map of exponent 10 and the recording's frames; the second (exponent
    # 80) into the same folder neither: what only the first wrote is gone, not left beside the second's files
    only_first = set(first["files"]) - set(_tree(runs / "a"))
    assert "maps/mipmap/reflection_s10.exr" in only_first and "recording/frames/000000.png" in only_first
    assert not (runs / "a" / "maps" / "mipmap" / "reflection_s10.exr").exists()
    assert {p["path"] for p in json.loads((runs / "a" / "manifest.json").read_text())["files"]} == set(_tree(runs / "a")) - {
        "manifest.json", OUTPUT_MARK}
    assert not list(runs.glob(".a.*"))  # no temporary or old folder left beside it


def test_a_runs_recording_without_its_frames_says_how_to_make_them_again(runs, tmp_path):
    how = f"arsim record {runs / 'a' / 'scenario.toml'} -o REC"
    r = arsim("run", runs / "s.toml", "-o", tmp_path / "o", "--recording", runs / "a" / "recording")
    assert_one_line_error(r, "frame images", "were not kept by `arsim run`", "--keep-recording", how)
    assert not (tmp_path / "o").exists()
    assert_one_line_error(arsim("info", runs / "a" / "recording"), "were not kept", how)
    assert_one_line_error(arsim("capture", runs / "a" / "recording", "-o", tmp_path / "c"), "were not kept", how)


def test_diff_of_a_run_against_itself_passes_with_flip_zero(runs, tmp_path):
    r = arsim("diff", runs / "a", runs / "replay", "-o", tmp_path / "d")
    assert r.returncode == 0, r.stdout + r.stderr
    summary = json.loads((tmp_path / "d" / "diff.json").read_text())
    assert summary["passed"] and summary["flip_max"] == 0.0 and summary["frames"] == 4


def test_diff_against_a_changed_exponent_fails_and_lights_up_that_object_only(runs, tmp_path):
    r = arsim("diff", runs / "a", runs / "changed", "-o", tmp_path / "d")
    assert r.returncode == 1, r.stdout + r.stderr
    summary = json.loads((tmp_path / "d" / "diff.json").read_text())
    assert not summary["passed"] and summary["flip_max"] > 0
    # Where the frames differ: on one object. The objects are the pixels where the frame differs from the
    # camera's (the background pass copies it); the FLIP error above 0.05 lies within one of them (widened
    # by FLIP's filters), in every frame where the two are apart on screen.
    import cv2

    from arsim.core.png import read_frame

    checked = 0
    for frame in summary["per_frame"]:
        name = frame["name"]
        a, b = read_frame(runs / "a" / "frames" / name), read_frame(runs / "changed" / "frames" / name)
        camera = read_frame(runs / "rec" / "ar" / "frames" / name)  # (the run's recording: without its frames)
        objects = cv2.dilate((a != camera).any(axis=-1).astype(np.uint8), np.ones((9, 9), np.uint8))
        count, labels = cv2.connectedComponents(objects)
        _, error = compare_images(a, b)
        if count - 1 != 2 or error is None:  # (up close the sphere overlaps the torus on screen)
            continue
        hot = error > 0.05
        assert hot.sum() > 10
        lit = {int(label) for label in np.unique(labels[hot])}
        assert len(lit) == 1 and 0 not in lit  # every hot pixel on one object
        # The other object changes a little, and only a little: the tone mapping's average luminance
        # spans every object's pixels, so a brighter sphere darkens the torus by a few 8-bit steps.
        assert error[labels == 3 - lit.pop()].max() < 0.05
        checked += 1
    assert checked >= 1
    worst = summary["worst_frame"]
    assert (tmp_path / "d" / "heatmaps" / worst).is_file() and "FAILED" in (tmp_path / "d" / "index.html").read_text()


def test_run_against_a_baseline_and_the_fixture(runs, tmp_path):
    baseline = tmp_path / "baseline"
    update_baseline(runs / "a", baseline)
    assert sorted(p.name for p in (baseline / "frames").iterdir()) == sorted(p.name for p in (runs / "a" / "frames").glob("*.png"))
    assert assert_frames_match(runs / "replay", baseline).passed
    with pytest.raises(AssertionError, match=r"do not match the baseline.*\n.*over FLIP 0\n  \d+\.png: FLIP mean"):
        assert_frames_match(runs / "changed", baseline, out_dir=tmp_path / "d")


def test_the_arsim_baseline_fixture_in_a_users_suite(runs, tmp_path):
    """The plugin as a user's suite sees it: a passing and a failing comparison."""
    import subprocess
    import sys

    test_file = tmp_path / "test_user.py"
    test_file.write_text(f"""
def test_same(arsim_baseline):
    arsim_baseline({str(runs / 'replay')!r}, {str(runs / 'a')!r})

def test_changed(arsim_baseline):
    arsim_baseline({str(runs / 'changed')!r}, {str(runs / 'a')!r})
""")
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", str(test_file)], capture_output=True,
                       text=True, cwd=tmp_path)
    assert "1 failed, 1 passed" in r.stdout, r.stdout
    assert "do not match the baseline" in r.stdout and "heatmap heatmaps/" in r.stdout


def test_diff_of_two_images(tmp_path):
    a = np.zeros((40, 60, 3), np.uint8)
    b = a.copy()
    b[10:14, 20:24] = 200
    (tmp_path / "a.png").write_bytes(png_bytes(a))
    (tmp_path / "b.png").write_bytes(png_bytes(b))
    result = run_diff(tmp_path / "a.png", tmp_path / "b.png", max_flip=0.5)
    frame = result.frames[0]
    assert frame.differing_pixels == 16 and frame.max_abs == 200 and 0 < frame.flip_mean < 0.5 and result.passed
    assert 10 < frame.psnr_db < 40
    assert not run_diff(tmp_path / "a.png", tmp_path / "b.png").passed  # default: any difference fails


def test_bad_inputs_are_refused_in_one_line(tmp_path, runs):
    (tmp_path / "broken.toml").write_text("[run\nname = ")
    assert_one_line_error(arsim("run", tmp_path / "broken.toml", "-o", tmp_path / "o"), "broken.toml")
    (tmp_path / "empty").mkdir()
    assert_one_line_error(arsim("run", runs / "s.toml", "-o", tmp_path / "o", "--baseline", tmp_path / "empty"),
                          "no frames")
    (tmp_path / "small.png").write_bytes(png_bytes(np.zeros((10, 10, 3), np.uint8)))
    (tmp_path / "big.png").write_bytes(png_bytes(np.zeros((12, 10, 3), np.uint8)))
    assert_one_line_error(arsim("diff", tmp_path / "small.png", tmp_path / "big.png"), "sizes differ")
    assert_one_line_error(arsim("diff", tmp_path / "small.png", tmp_path / "nothing.png"), "no such file")
    assert_one_line_error(arsim("run", runs / "s.toml", "-o", tmp_path / "o", "--recording", tmp_path / "nothing"),
                          "no such recording")


def test_info_checks_a_run_against_its_manifest(runs, tmp_path):
    import shutil

    r = arsim("info", runs / "a")
    assert r.returncode == 0 and "scenario small (seed 7), complete:" in r.stdout, r.stdout + r.stderr
    summary = json.loads(arsim("info", runs / "replay", "--json").stdout)
    assert summary["files"] > 10 and "recording" not in summary["seconds_per_stage"]  # a replay records nothing
    broken = tmp_path / "broken"
    shutil.copytree(runs / "a", broken)
    (broken / "session.mp4").unlink()
    assert_one_line_error(arsim("info", broken), "session.mp4 is missing")
    shutil.copy2(runs / "a" / "session.mp4", broken / "session.mp4")
    assert arsim("info", broken).returncode == 0
    with open(broken / "report" / "index.html", "a") as page:
        page.write("<!-- edited -->")
    assert_one_line_error(arsim("info", broken), "report/index.html has", "changed since the run")
    (broken / "manifest.json").write_text("{")
    assert_one_line_error(arsim("info", broken), "not a manifest arsim wrote")


def test_the_manifest_does_not_list_itself(tmp_path):
    """A run into a folder holding an earlier run's manifest.json lists the files, not that manifest."""
    from arsim.run.pipeline import FILE_ROLES, _files_under

    (tmp_path / "capture").mkdir()
    (tmp_path / "capture" / "env.exr").write_bytes(b"x" * 10)
    (tmp_path / "manifest.json").write_text("{}")
    assert _files_under(tmp_path, FILE_ROLES) == [{"path": "capture/env.exr", "role": FILE_ROLES["capture/env.exr"],
                                                   "bytes": 10}]


def test_the_report_opens_with_verdicts_units_and_thresholds(runs):
    page = (runs / "a" / "report" / "index.html").read_text()
    summary = page[page.index('id="summary"'):page.index('id="capture"')]
    assert page.index('id="summary"') < page.index('id="scenario"')  # the verdicts first, the scenario last
    for stage in ("capture", "maps", "tracking", "AR frames", "frame budget"):
        assert f"<td>{stage}</td>" in summary, stage
    assert "degrees" in summary and "%" in summary and "pass ≤ 0.250 degrees" in summary  # [report]'s defaults
    assert summary.count('class="pass"') + summary.count('class="warn"') + summary.count('class="fail"') >= 5
    assert 'href="../session.mp4"' in page and 'href="../manifest.json"' in page
    # the frames shown beside their truth frames and FLIP maps; the maps beside the truth's and their error
    assert (runs / "a" / "frames" / "truth" / "000000.png").is_file() and (runs / "a" / "report" / "frame_000000.png").is_file()
    assert all((runs / "a" / "maps" / f"vs_truth_{m}.png").is_file() for m in ("fast", "mipmap"))
    assert (runs / "a" / "maps" / "maps.png").is_file()


def test_every_figure_of_a_run_is_registered_with_a_unit_and_meaning(runs):
    from arsim.evaluate.registry import figures_of, metric_for

    figures = figures_of(json.loads((runs / "a" / "metrics.json").read_text()))
    assert len(figures) > 60
    unregistered = [p for p in figures if metric_for(p) is None]
    assert not unregistered, unregistered
    assert all(metric_for(p).meaning for p in figures)


def test_diff_of_two_runs_lists_every_figure_and_fails_where_one_got_worse(runs, tmp_path):
    import shutil

    # the same run with one figure made worse beyond its tolerance (FLIP +50 %) and one time much worse (not gated)
    worse = tmp_path / "worse"
    shutil.copytree(runs / "a", worse)
    metrics = json.loads((worse / "metrics.json").read_text())
    flip = metrics["session"]["flip_mean"]
    metrics["session"]["flip_mean"] = flip * 1.5 + 0.01
    metrics["capture"]["seconds_online"] += 100.0
    (worse / "metrics.json").write_text(json.dumps(metrics))
    r = arsim("diff", runs / "a", worse, "-o", tmp_path / "d")
    assert r.returncode == 1, r.stdout + r.stderr
    assert "`session.flip_mean`" in r.stdout and "| worse |" in r.stdout and "worse (timed: not gated)" in r.stdout
    summary = json.loads((tmp_path / "d" / "diff.json").read_text())
    assert summary["metrics_worse"] == ["session.flip_mean"]
    row = next(m for m in summary["metrics"] if m["path"] == "session.flip_mean")
    assert row["a"] == pytest.approx(flip) and row["b"] == pytest.approx(flip * 1.5 + 0.01)
    assert "| AR frames' FLIP |" in (tmp_path / "d" / "metrics.md").read_text()
    # the other way round the FLIP got better: the frames are equal, nothing is worse but the time (not gated)
    assert arsim("diff", worse, runs / "a").returncode == 0
    assert arsim("diff", runs / "a", worse, "--gate-times").returncode == 1


def test_the_summary_shows_a_baselines_figures_beside_the_runs(runs):
    from arsim.run.report import _verdict_section
    from arsim.scenario import load_scenario

    metrics = json.loads((runs / "a" / "metrics.json").read_text())
    baseline = json.loads(json.dumps(metrics))
    baseline["session"]["flip_mean"] = metrics["session"]["flip_mean"] / 2  # the run got worse than the baseline
    html = _verdict_section(metrics, load_scenario(runs / "s.toml"), baseline)
    assert "<th>baseline</th><th>change</th>" in html
    flip_row = next(row for row in html.split("<tr>") if "<td>AR frames</td>" in row)
    assert "(worse)" in flip_row and f"+{metrics['session']['flip_mean'] / 2:.4g}" in flip_row
    capture_row = next(row for row in html.split("<tr>") if "<td>capture</td>" in row)
    assert "(worse)" not in capture_row and "+0<" in capture_row
