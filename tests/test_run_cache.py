"""The run cache (README: The run cache): each stage of `arsim run` reused where its key matches, with outputs
byte-identical to a run computing every stage; a change in a setting a stage reads recomputes that stage and the
later ones only; an entry that fails its hashes is computed again; `arsim batch` computes a shared stage once."""

import dataclasses
import fnmatch
import json
import shutil

import pytest

from arsim.run.cache import StageCache, code_files
from arsim.run.pipeline import STAGES, TIMED_FILES, recording_digest, recording_key, stage_keys
from arsim.scenario import load_scenario
from tests.conftest import ENVMAPS
from tests.test_cli import arsim
from tests.test_run import SMALL

LATER = {stage: set(STAGES[k:]) for k, stage in enumerate(STAGES)}  # a stage and the ones after it


def _small(**replace: str) -> str:
    """tests/test_run.py's small scenario, its AR path shortened to 2 s (the look-away in it)."""
    text = SMALL.format(env=ENVMAPS[1].as_posix(), exponent=80.0)
    text = text.replace("duration_s = 4.0", "duration_s = 2.0").replace("start_s = 1.5\nend_s = 2.5", "start_s = 0.8\nend_s = 1.2")
    for old, new in replace.items():
        assert old in text
        text = text.replace(old, new)
    return text


def _files(root):
    return {p.relative_to(root).as_posix(): p for p in root.rglob("*") if p.is_file()}


def _differing(a, b) -> list[str]:
    fa, fb = _files(a), _files(b)
    assert set(fa) == set(fb), sorted(set(fa) ^ set(fb))
    return sorted(name for name in fa if fa[name].read_bytes() != fb[name].read_bytes())


def _status(run) -> dict[str, str]:
    return {name: s["status"] for name, s in json.loads((run / "manifest.json").read_text())["stages"].items()}


def _computed(run) -> set[str]:
    return {name for name, status in _status(run).items() if status == "computed"}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A batch of two scenarios sharing their recording (they differ in [render] key) into a new cache, the first
    run again (warm), the first run without the cache, and a run with [capture] capture_size changed."""
    root = tmp_path_factory.mktemp("cache_runs")
    cache = root / "cache"
    (root / "s.toml").write_text(_small())
    (root / "r.toml").write_text(_small(**{"[render]\n": "[render]\nkey = 0.3\n"}))
    (root / "c.toml").write_text(_small(**{"capture_size = 128": "capture_size = 64"}))
    (root / "t.toml").write_text(_small(**{"[render]\n": "[render]\nkey = 0.35\n"}))
    done = {"batch": arsim("batch", root / "s.toml", root / "r.toml", "-o", root / "batch", "--workers", "2", "--cache", cache),
            "warm": arsim("run", root / "s.toml", "-o", root / "warm", "--cache", cache),
            "fresh": arsim("run", root / "s.toml", "-o", root / "fresh", "--no-cache"),
            "capture": arsim("run", root / "c.toml", "-o", root / "capture", "--cache", cache),
            "render": arsim("run", root / "t.toml", "-o", root / "render", "--cache", cache),
            "render_fresh": arsim("run", root / "t.toml", "-o", root / "render_fresh", "--no-cache")}
    for name, r in done.items():
        assert r.returncode == 0, (name, r.stdout, r.stderr)
    done["root"] = root
    return done


def test_a_batch_computes_the_stages_its_scenarios_share_once(runs):
    root = runs["root"]
    s, r = _status(root / "batch" / "s"), _status(root / "batch" / "r")
    for stage in ("recording", "capture", "estimates", "maps"):  # shared: one computes, the other reuses
        assert sorted([s[stage], r[stage]]) == ["computed", "reused"], stage
    assert s["session"] == r["session"] == s["report"] == r["report"] == "computed"
    timing = json.loads((root / "batch" / "summary.json").read_text())["timing"]
    assert timing["stages"]["s"] == s and timing["stages"]["r"] == r


def test_a_warm_run_reuses_every_stage_byte_identical_to_a_fresh_run(runs):
    root = runs["root"]
    warm, fresh, first = root / "warm", root / "fresh", root / "batch" / "s"
    assert _computed(warm) == set() and _computed(fresh) == set(STAGES)
    # against the run that filled the cache: every file the same but the manifest (what it says of the stages)
    assert _differing(warm, first) == ["manifest.json"]
    # against a run computing every stage: only the files carrying measured times differ
    differing = _differing(warm, fresh)
    assert "manifest.json" in differing
    assert all(any(fnmatch.fnmatch(name, p) for p in TIMED_FILES) for name in differing), differing
    for name in ("frames/000000.png", "session.mp4", "capture/env.exr", "recording/meta.json", "maps/mipmap/reflection_s80.exr",
                 "estimates/estimates.jsonl", "estimates/scores.json"):
        assert name in _files(warm) and name not in differing, name
    w, f = json.loads((warm / "manifest.json").read_text()), json.loads((fresh / "manifest.json").read_text())
    assert w["metrics"]["session"]["frames_rendered"] == f["metrics"]["session"]["frames_rendered"]
    for stage in STAGES:
        assert w["stages"][stage]["key"] == f["stages"][stage]["key"], stage
        assert w["stages"][stage]["from"].startswith(str(root / "cache")) and f["stages"][stage]["from"] is None
        assert f["stages"][stage]["stored"] is None and stage in w["seconds_per_stage"]
    lines = [line for line in runs["warm"].stdout.splitlines() if line.startswith("  ")]
    assert [line.split()[:2] for line in lines] == [[stage, "reused"] for stage in STAGES]


def test_a_render_setting_recomputes_the_session_and_report_only(runs):
    root = runs["root"]
    a, b = root / "batch" / "s", root / "batch" / "r"
    keys = [json.loads((run / "manifest.json").read_text())["stages"] for run in (a, b)]
    assert [s for s in STAGES if keys[0][s]["key"] != keys[1][s]["key"]] == ["session", "report"]
    # the reused recording carries the run's own scenario, as one recorded now would
    meta = json.loads((b / "recording" / "meta.json").read_text())
    assert "key = 0.3" in meta["scenario_toml"] and "key = 0.3" not in (a / "recording" / "meta.json").read_text()
    assert _differing(a / "capture", b / "capture") in ([], ["metrics.json"])


def test_a_render_setting_renders_again_with_the_poses_tracked_before_byte_identical(runs):
    root = runs["root"]
    render, fresh = root / "render", root / "render_fresh"
    assert _computed(render) == {"session", "report"}
    sessions = [json.loads((run / "manifest.json").read_text())["stages"]["session"] for run in (render, fresh)]
    assert sessions[0]["tracking"]["status"] == "reused" and sessions[1]["tracking"]["status"] == "computed"
    assert sessions[0]["tracking"]["key"] == sessions[1]["tracking"]["key"]
    # the estimates' maps too: made from the same estimates for the same objects and size
    assert sessions[0]["lit_maps"]["status"] == "reused" and sessions[1]["lit_maps"]["status"] == "computed"
    assert sessions[0]["lit_maps"]["key"] == sessions[1]["lit_maps"]["key"]
    differing = _differing(render, fresh)
    assert all(any(fnmatch.fnmatch(name, p) for p in TIMED_FILES) for name in differing), differing
    assert "session.mp4" in _files(render) and "frames/000000.png" in _files(render)
    # the profile still has the tracking step, with the times measured when the poses were tracked
    for run in (render, fresh):
        track = json.loads((run / "profile" / "profile.json").read_text())["runs"][0]["steps"]["track"]["cpu"]
        assert track["p50"] > 0, (run, track)


def test_a_capture_setting_recomputes_the_capture_and_later_stages(runs):
    assert _status(runs["root"] / "capture")["recording"] == "reused"
    assert _computed(runs["root"] / "capture") == LATER["capture"]
    # other estimates: the estimates' maps are made again
    lit = [json.loads((runs["root"] / run / "manifest.json").read_text())["stages"]["session"]["lit_maps"]
           for run in ("capture", "render")]
    assert lit[0]["status"] == "computed" and lit[0]["key"] != lit[1]["key"]


def test_the_estimates_maps_are_keyed_by_what_they_are_made_from_and_round_trip(tmp_path):
    import numpy as np

    from arsim.lighting.mapset import MapSet
    from arsim.run.pipeline import _load_lit_maps, _save_lit_maps, lit_maps_key

    base = lit_maps_key("e", {"fast": [1.0, 80.0]}, 128)
    assert base == lit_maps_key("e", {"fast": [80, 1]}, 128)  # (the exponents' order and type do not count)
    changed = {lit_maps_key("f", {"fast": [1.0, 80.0]}, 128), lit_maps_key("e", {"fast": [1.0, 40.0]}, 128),
               lit_maps_key("e", {"mipmap": [1.0, 80.0]}, 128), lit_maps_key("e", {"fast": [1.0, 80.0]}, 64)}
    assert base not in changed and len(changed) == 4
    rng = np.random.default_rng(0)
    maps = {name: {m: MapSet(m, {s: rng.random((8, 8, 3)).astype(np.float32) for s in (1.0, 80.0, 1280.0)}, f"{name} estimate")
                   for m in ("fast", "mipmap")} for name in ("capture", "single")}
    _save_lit_maps(maps, tmp_path / "state")
    loaded = _load_lit_maps(tmp_path / "state")
    assert loaded.keys() == maps.keys()
    for name, sets in maps.items():
        for m, ms in sets.items():
            assert loaded[name][m].source == ms.source and loaded[name][m].exponents == ms.exponents
            assert all(np.array_equal(loaded[name][m][s], ms[s]) and loaded[name][m][s].dtype == np.float32 for s in ms.exponents)


def test_a_corrupted_entry_is_detected_and_computed_again(runs, tmp_path):
    root = runs["root"]
    cache = tmp_path / "cache"
    shutil.copytree(root / "cache", cache)
    key = json.loads((root / "warm" / "manifest.json").read_text())["stages"]
    capture, session = cache / "capture" / key["capture"]["key"], cache / "session" / key["session"]["key"]
    env = capture / "files" / "capture" / "env.exr"
    data = bytearray(env.read_bytes())
    data[len(data) // 2] ^= 1  # one bit: the same size
    env.write_bytes(bytes(data))
    (session / "state" / "arrays.npz").unlink()
    r = arsim("run", root / "s.toml", "-o", tmp_path / "run", "--cache", cache)
    assert r.returncode == 0, r.stderr
    assert _computed(tmp_path / "run") == {"capture", "session"}
    differing = _differing(tmp_path / "run", root / "warm")
    assert all(any(fnmatch.fnmatch(name, p) for p in TIMED_FILES) for name in differing), differing
    assert StageCache(cache).lookup("capture", key["capture"]["key"]) is not None  # stored whole again
    # an extra file in an entry fails it too
    (capture / "files" / "extra.txt").write_text("x")
    assert StageCache(cache).lookup("capture", key["capture"]["key"]) is None and not capture.exists()


def test_cache_info_and_clear(runs, tmp_path):
    cache = tmp_path / "cache"
    shutil.copytree(runs["root"] / "cache", cache)
    info = json.loads(arsim("cache", "info", "--cache", cache, "--json").stdout)
    # (the session's tracking and the estimates' maps have entries of their own)
    assert set(info["stages"]) == set(STAGES) | {"tracking", "lit_maps"} and info["entries"] >= 9 and info["bytes"] > 0
    assert info["stages"]["recording"]["entries"] == 1 and info["stages"]["capture"]["entries"] == 2
    r = arsim("cache", "clear", "--cache", cache)
    assert r.returncode == 0 and f"removed {info['entries']} entries" in r.stdout
    assert json.loads(arsim("cache", "info", "--cache", cache, "--json").stdout)["entries"] == 0


def test_the_size_bound_removes_the_least_recently_used_entries(tmp_path):
    cache = StageCache(tmp_path / "c", max_bytes=250)
    (tmp_path / "run").mkdir()
    for k in range(3):
        (tmp_path / "run" / f"f{k}").write_bytes(bytes(100))
        cache.store("maps", f"k{k}", tmp_path / "run", [f"f{k}"])
    assert cache.lookup("maps", "k0") is None and cache.lookup("maps", "k2") is not None
    assert cache.lookup("maps", "k1") is not None
    assert cache.restore(cache.lookup("maps", "k1"), tmp_path / "out") is None and (tmp_path / "out" / "f1").read_bytes() == bytes(100)


# Keys: a change in any setting a stage reads changes its key and the later stages', not the earlier ones'.


@pytest.fixture(scope="module")
def objects(tmp_path_factory):
    """The small scenario's objects (the settings changed below leave them as they are)."""
    from arsim.render.content import scene_objects

    path = tmp_path_factory.mktemp("objects") / "s.toml"
    path.write_text(_small())
    return scene_objects(load_scenario(path).render)


def _keys(scenario, tmp_path, objects, source="s.toml") -> dict[str, str]:
    """Every stage's key, the recording's content hash from a recording folder whose meta.json carries the
    scenario (as a recording made from it would)."""
    from arsim.scenario.loader import scenario_to_toml

    folder = tmp_path / "rec"
    folder.mkdir(exist_ok=True)
    (folder / "meta.json").write_text(json.dumps({"seed": 1, "scenario_toml": scenario_to_toml(scenario, portable=True)}))
    content = recording_digest(folder, {"meta.json": "0" * 64, "frames/000000.png": "1" * 64}, scenario)
    return {"recording": recording_key(scenario)} | stage_keys(scenario, source, content, objects)


def _replace(scenario, dotted: str, value):
    section, _, rest = dotted.partition(".")
    inner = getattr(scenario, section)
    if "." in rest:
        return dataclasses.replace(scenario, **{section: _replace(inner, rest, value)})
    return dataclasses.replace(scenario, **{section: dataclasses.replace(inner, **{rest: value})})


CHANGES = [  # (setting, new value, the first stage it invalidates)
    ("run.seed", 8, "recording"),
    ("environment.intensity", 2.0, "recording"),
    ("device.camera.fps", 12.0, "recording"),
    ("capture.turns", 3.0, "recording"),
    ("ar.near_m", 0.35, "recording"),
    ("capture.capture_size", 64, "capture"),
    ("capture.refine", False, "capture"),
    ("capture.align_every", 2, "capture"),
    ("render.map_size", 64, "maps"),
    ("render.methods", ("mipmap", "accurate"), "maps"),
    ("render.key", 0.3, "session"),
    ("render.flip_every", 2, "session"),
    ("ar.detector", "opencv", "session"),
    ("profile.budget_ms", 16.6, "session"),
    ("run.name", "other", "report"),
    ("profile.tile", "16", "report"),
]


@pytest.mark.parametrize("setting, value, first", CHANGES, ids=[c[0] for c in CHANGES])
def test_a_setting_changes_the_keys_of_the_stages_that_read_it_and_the_later_ones(setting, value, first, tmp_path, objects):
    (tmp_path / "s.toml").write_text(_small())
    scenario = load_scenario(tmp_path / "s.toml")
    changed = _replace(scenario, setting, value)
    assert changed != scenario
    before, after = _keys(scenario, tmp_path, objects), _keys(changed, tmp_path, objects)
    assert {s for s in STAGES if before[s] != after[s]} == LATER[first]


def test_the_environment_map_counts_by_its_content_and_the_source_in_the_report(tmp_path, objects):
    env = tmp_path / "env.exr"
    shutil.copyfile(ENVMAPS[1], env)
    (tmp_path / "s.toml").write_text(_small().replace(ENVMAPS[1].as_posix(), env.as_posix()))
    scenario = load_scenario(tmp_path / "s.toml")
    before = _keys(scenario, tmp_path, objects)
    assert _keys(scenario, tmp_path, objects) == before  # deterministic
    with open(env, "ab") as f:
        f.write(b"\0")  # the same path, another content
    after = _keys(scenario, tmp_path, objects)
    assert {s for s, k in after.items() if k != before[s]} == set(STAGES)
    assert {s for s, k in _keys(scenario, tmp_path, objects, source="t.toml").items() if k != after[s]} == {"report"}


def test_each_stage_hashes_the_code_it_runs():
    recording = code_files(("arsim.sensors.recording",))
    assert "sensors/recording.py" in recording and "core/files.py" in recording and "__init__.py" in recording
    assert not any(p.startswith(("render/", "run/", "capture/", "evaluate/")) for p in recording)
    from arsim.run.pipeline import RUN_FILES, STAGE_CODE

    session = code_files(STAGE_CODE["session"], RUN_FILES)
    assert "render/session.py" in session and "run/pipeline.py" in session and "sensors/recording.py" in session
    maps = code_files(STAGE_CODE["maps"], RUN_FILES)
    assert "lighting/methods.py" in maps and "render/session.py" not in maps


def test_a_batch_passes_its_cache_to_each_run(tmp_path):
    from pathlib import Path

    from arsim.run.batch import run_command

    base = run_command(Path("s.toml"), tmp_path, None, 0.0)
    assert "--cache" not in base and "--no-cache" not in base  # the default cache
    assert run_command(Path("s.toml"), tmp_path, None, 0.0, "off")[-1] == "--no-cache"
    assert run_command(Path("s.toml"), tmp_path, None, 0.0, "/c")[-2:] == ["--cache", "/c"]


def test_a_recordings_frames_are_borrowed_from_the_entry_never_copied(tmp_path, monkeypatch):
    """A run leaves its recording's frame images out at its end: restored from an entry on another file system
    (no hard link), they are symbolic links into the entry, where the other outputs are copies."""
    import errno
    import os

    cache = StageCache(tmp_path / "c")
    run = tmp_path / "run"
    (run / "recording" / "frames").mkdir(parents=True)
    (run / "recording" / "frames" / "000000.png").write_bytes(b"png")
    (run / "recording" / "frames.csv").write_text("t_ns,exposure_ns,iso,file\n")
    cache.store("recording", "k", run, ["recording/frames/000000.png", "recording/frames.csv"])

    def across_file_systems(source, target):
        raise OSError(errno.EXDEV, "Invalid cross-device link")

    monkeypatch.setattr(os, "link", across_file_systems)
    out = tmp_path / "out"
    cache.restore(cache.lookup("recording", "k"), out, lambda rel: rel.endswith(".png"))
    frame, csv = out / "recording" / "frames" / "000000.png", out / "recording" / "frames.csv"
    assert frame.is_symlink() and frame.resolve() == (tmp_path / "c" / "recording" / "k" / "files" / "recording" / "frames"
                                                       / "000000.png").resolve() and frame.read_bytes() == b"png"
    assert not csv.is_symlink() and csv.read_text() == "t_ns,exposure_ns,iso,file\n"


def test_the_manifests_disk_counts_every_file_and_itself(tmp_path):
    from arsim.run.pipeline import FILE_ROLES, _files_under, _write_manifest

    (tmp_path / "capture").mkdir()
    (tmp_path / "capture" / "env.exr").write_bytes(bytes(999_995))  # the manifest's size crosses into 7 digits
    manifest = {"files": _files_under(tmp_path, FILE_ROLES)}
    _write_manifest(tmp_path, manifest)
    written = json.loads((tmp_path / "manifest.json").read_text())
    sizes = [p.stat().st_size for p in tmp_path.rglob("*") if p.is_file()]
    assert written["disk"] == {"files": 2, "bytes": sum(sizes)} and sum(sizes) > 10**6
