"""`arsim run`: a scenario end to end into one run directory (README: Runs end to end): the recording (or a
recording replayed), the captured probe against the truth, the maps of every method the scenario names
baked from the probe, the AR session's frames, its render-loop profile, the metrics of every stage, the
report and manifest.json.

Stages take a `stage(description)` context manager that yields update(fraction): the command line
shows it as a progress bar naming the stage.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from arsim import __version__
from arsim.core.conventions import anglemap_disk_mask
from arsim.core.errors import ArsimError
from arsim.core.files import json_text, write_text_atomic
from arsim.core.gl import create_gl_context
from arsim.core.png import kept_frames
from arsim.core.progress import quiet_stage
from arsim.core.resample import to_layout
from arsim.capture.response import RecoveredResponse
from arsim.evaluate.metrics import map_error
from arsim.run.cache import ENTRY, StageCache, code_digest, key_of, read_state, settings_digest, sha256_files, snapshot, write_state
from arsim.scenario.loader import scenario_to_toml
from arsim.scenario.sections import Scenario

STAGES = ("recording", "capture", "estimates", "maps", "session", "report")
KEPT_FRAME_BYTES = 3 * 1024**3  # a recording the run makes, kept decoded for its later stages (kept_frame_bytes)


def _files_under(out: Path, roles: dict[str, str]) -> list[dict]:
    """Every file of the run with its role: the first folder (or file name) it lies under names it. Not the
    manifest itself (a run into a folder that holds an earlier run's would list the old one's size)."""
    files = []
    for path in sorted(p for p in out.rglob("*") if p.is_file() and not p.name.startswith(".")):
        rel = path.relative_to(out).as_posix()
        if rel == "manifest.json":
            continue
        role = next((r for prefix, r in roles.items() if rel == prefix or rel.startswith(prefix + "/")), "other")
        files.append({"path": rel, "role": role, "bytes": path.stat().st_size})
    return files


FILE_ROLES = {
    "recording": "the recorded sweep and AR path (frames, IMU streams, truth)",
    "capture/env.exr": "the captured HDR light probe (angle map)",
    "capture/truth.exr": "the true environment at the probe's size",
    "capture": "capture metrics and plots",
    "estimates": "light estimates in the platforms' shapes, scored; the objects lit by each (frames/)",
    "maps": "maps baked from the captured probe, a folder per method",
    "frames": "frames rendered by the AR session",
    "session.mp4": "the AR session's video",
    "profile": "the render loop's profile: per step CPU and GL time",
    "metrics.json": "every stage's metrics",
    "scenario.toml": "the scenario as resolved",
    "report": "the HTML report",
}


# The files of a run that carry measured times (seconds, frame and step milliseconds, trace timestamps),
# which differ from run to run on any machine; every other file is byte-identical for the same scenario
# and seed (tests/test_run.py checks both).
TIMED_FILES = ("manifest.json", "metrics.json", "capture/metrics.json", "maps/*/bake.json", "profile/profile.json",
               "profile/profile.md", "profile/trace.json", "profile/timeline.png", "report/index.html")


def versions(gl_renderer: str) -> dict:
    import cv2
    import moderngl

    return {"arsim": __version__, "python": platform.python_version(), "numpy": np.__version__,
            "opencv": cv2.__version__, "moderngl": moderngl.__version__, "gl_renderer": gl_renderer}


# The arsim modules each stage runs (README: The run cache): a stage's key holds the sha256 of their source and
# of every arsim module they import, transitively, and of RUN_FILES (which orchestrate the stages; their own
# imports serve every stage, so they are hashed without being followed). The recording runs in sensors alone.
STAGE_CODE = {
    "recording": ("arsim.sensors.recording",),
    "capture": ("arsim.capture.pipeline", "arsim.evaluate.capture_report", "arsim.sensors.formats", "arsim.sensors.frames"),
    "estimates": ("arsim.estimate.series", "arsim.estimate.platforms", "arsim.estimate.shapes", "arsim.estimate.single_frame",
                  "arsim.evaluate.estimates", "arsim.capture.pipeline", "arsim.sensors.frames"),
    "maps": ("arsim.lighting.methods", "arsim.lighting.bake_output", "arsim.lighting.mapset", "arsim.evaluate.metrics",
             "arsim.evaluate.compare_methods", "arsim.core.gl", "arsim.core.conventions"),
    "session": ("arsim.render.session", "arsim.render.content", "arsim.evaluate.flip", "arsim.evaluate.profile",
                "arsim.evaluate.session", "arsim.estimate.lit", "arsim.evaluate.estimates"),
    "report": ("arsim.run.report", "arsim.evaluate.estimates", "arsim.evaluate.session", "arsim.scenario.loader"),
}
RUN_FILES = ("run/pipeline.py", "run/stages.py", "run/cache.py")
# [capture]'s settings of the capture alone, and [ar]'s of the AR session alone; the others shape the recording
CAPTURE_ONLY = ("align_every", "refine", "capture_size")
AR_SESSION_ONLY = ("detector", "fusion")


def recording_settings(scenario: Scenario) -> dict:
    """What the recording depends on: [run] seed, [environment] (the map file by content), [device], [capture]'s
    sweep settings and [ar]."""
    sweep = {k: v for k, v in settings_digest(scenario.capture).items() if k not in CAPTURE_ONLY}
    ar = {k: v for k, v in settings_digest(scenario.ar).items() if k not in AR_SESSION_ONLY}
    return {"seed": scenario.run.seed, "environment": settings_digest(scenario.environment),
            "device": settings_digest(scenario.device), "capture": sweep, "ar": ar}


def recording_key(scenario: Scenario) -> str:
    return key_of("recording", {"settings": recording_settings(scenario), "code": code_digest(STAGE_CODE["recording"])})


def maps_plan(objects: list, r) -> tuple[dict[str, list[float]], list[str], list[float]]:
    """The maps a run bakes: per method the exponents its objects need, every method (those and [render]
    methods), and every exponent."""
    from arsim.render.session import maps_needed

    needed = maps_needed(objects, r.method)
    return needed, list(dict.fromkeys([*needed, *r.methods])), sorted({s for ss in needed.values() for s in ss})


def stage_keys(scenario: Scenario, source: str, content: str, objects: list) -> dict[str, str]:
    """The keys of the stages after the recording: content is the recording's content hash (recording_digest),
    objects the scenario's (render.content.scene_objects), whose materials name the maps baked."""
    r = scenario.render
    _, methods, exponents = maps_plan(objects, r)
    code = {name: code_digest(modules, RUN_FILES) for name, modules in STAGE_CODE.items() if name != "recording"}
    keys = {"capture": key_of("capture", {"recording": content, "code": code["capture"]})}
    keys["estimates"] = key_of("estimates", {"capture": keys["capture"], "code": code["estimates"]})
    keys["maps"] = key_of("maps", {"capture": keys["capture"], "map_size": r.map_size,
                                   "methods": methods, "exponents": exponents, "code": code["maps"]})
    keys["session"] = key_of("session", {"maps": keys["maps"], "estimates": keys["estimates"], "render": settings_digest(r),
                                         "ar": {k: getattr(scenario.ar, k) for k in AR_SESSION_ONLY},
                                         "budget_ms": scenario.profile.budget_ms, "code": code["session"]})
    keys["report"] = key_of("report", {"session": keys["session"], "scenario": settings_digest(scenario), "source": source,
                                       "code": code["report"]})
    return keys


# The tracker's code: the session reuses the frames' poses where the recording, the response, [ar]'s tracker
# settings and this code are the same (a change in [render] alone renders again without tracking again).
TRACKING_CODE = ("arsim.tracking.fusion", "arsim.tracking.apriltag", "arsim.tracking.detectors", "arsim.render.loop")


def tracking_key(scenario: Scenario, capture_key: str, every: int) -> str:
    """The key of the session's tracking: the capture's key (the recording and the response that linearises the
    frames), [ar]'s tracker settings, the frames tracked (every k-th) and the tracker's code."""
    return key_of("tracking", {"capture": capture_key, "ar": {k: getattr(scenario.ar, k) for k in AR_SESSION_ONLY},
                               "every": every, "code": code_digest(TRACKING_CODE, RUN_FILES)})


# The estimates' maps: the session reuses them where the estimates, the maps the objects need, their size and
# this code are the same (a change in [render] key, white or the like renders again without making them again).
LIT_MAPS_CODE = ("arsim.estimate.lit",)


def lit_maps_key(estimates_key: str, needed: dict[str, list[float]], map_size: int) -> str:
    """The key of the estimates' maps (stages.lit_maps): the estimates' key, the methods and exponents the
    objects need, the maps' size and estimate.lit's code."""
    return key_of("lit_maps", {"estimates": estimates_key, "needed": {m: sorted(map(float, e)) for m, e in needed.items()},
                               "map_size": map_size, "code": code_digest(LIT_MAPS_CODE, RUN_FILES)})


def _save_lit_maps(maps: dict[str, dict], folder: Path) -> None:
    """stages.lit_maps' MapSets as arrays, named estimator/method/exponent."""
    write_state(folder, {name: {m: {"source": ms.source, "exponents": list(ms.exponents)} for m, ms in sets.items()}
                         for name, sets in maps.items()},
                {f"{name}|{m}|{s!r}": ms[s] for name, sets in maps.items() for m, ms in sets.items() for s in ms.exponents})


def _load_lit_maps(folder: Path) -> dict[str, dict]:
    from arsim.lighting.mapset import MapSet

    data, a = read_state(folder)
    return {name: {m: MapSet(m, {float(s): a[f"{name}|{m}|{float(s)!r}"] for s in d["exponents"]}, d["source"])
                   for m, d in sets.items()} for name, sets in data.items()}


def _save_tracked(tracked: dict, folder: Path) -> None:
    """The session's poses per frame (render.session.SessionResult.tracked) as arrays; None as NaN."""
    k = sorted(tracked)
    poses = [tracked[i][0] for i in k]
    nan = np.full((3, 3), np.nan)
    write_state(folder, None, {
        "frames": np.asarray(k, np.int64), "track_ms": np.asarray([tracked[i][1] for i in k], np.float64),
        "found": np.asarray([p.found for p in poses]),
        "rotation": np.stack([p.rotation if p.found else nan for p in poses]) if poses else np.zeros((0, 3, 3)),
        "translation": np.stack([p.translation if p.found else nan[0] for p in poses]) if poses else np.zeros((0, 3)),
        "corners": np.stack([p.corners if p.corners is not None else np.full((4, 2), np.nan) for p in poses])
        if poses else np.zeros((0, 4, 2)),
        "has_corners": np.asarray([p.corners is not None for p in poses]),
        "extrapolated": np.asarray([p.extrapolated for p in poses]),
        "since_tag_s": np.asarray([p.since_tag_s for p in poses], np.float64),
        "sigma_rotation_deg": np.asarray([np.nan if p.sigma_rotation_deg is None else p.sigma_rotation_deg for p in poses]),
        "sigma_position_m": np.asarray([np.nan if p.sigma_position_m is None else p.sigma_position_m for p in poses])})


def _load_tracked(folder: Path) -> dict:
    from arsim.tracking.apriltag import TagPose

    _, a = read_state(folder)
    tracked = {}
    for n, k in enumerate(a["frames"]):
        found = bool(a["found"][n])
        sigma_r, sigma_p = float(a["sigma_rotation_deg"][n]), float(a["sigma_position_m"][n])
        pose = TagPose(a["rotation"][n] if found else None, a["translation"][n] if found else None,
                       a["corners"][n] if a["has_corners"][n] else None, bool(a["extrapolated"][n]),
                       float(a["since_tag_s"][n]), None if np.isnan(sigma_r) else sigma_r, None if np.isnan(sigma_p) else sigma_p)
        tracked[int(k)] = (pose, float(a["track_ms"][n]))
    return tracked


def _recorded_settings(scenario: Scenario | None) -> dict | None:
    """What of the scenario a recording carries (its meta.json's scenario_toml) the later stages read: the
    recording's settings and all of [capture] (the capture takes its settings from the recording)."""
    if scenario is None:
        return None
    return recording_settings(scenario) | {"capture": settings_digest(scenario.capture)}


def recording_digest(folder: Path, hashes: dict[str, str], recorded: Scenario | None) -> str:
    """A recording's content hash: every file's sha256 (hashes: path under folder -> sha256), a meta.json's
    scenario_toml counted by what the later stages read of it (a reused recording carries the run's own
    scenario, which may differ in [render])."""
    h = hashlib.sha256()
    for rel in sorted(hashes):
        digest = hashes[rel]
        if Path(rel).name == "meta.json":
            try:
                meta = json.loads((folder / rel).read_text(encoding="utf-8"))
            except (OSError, ValueError):
                meta = None
            if isinstance(meta, dict) and "scenario_toml" in meta:
                meta["scenario_toml"] = _recorded_settings(recorded)
                digest = hashlib.sha256(json.dumps(meta, sort_keys=True, default=str).encode()).hexdigest()
        h.update(f"{rel}\0{digest}\0".encode())
    return h.hexdigest()


def _hash_files(root: Path, rels) -> dict[str, str]:
    rels = list(rels)
    return dict(zip(rels, sha256_files([root / rel for rel in rels])))


def _with_scenario_toml(folder: Path, scenario: Scenario) -> None:
    """A reused recording's meta.json files made to carry this run's scenario, as a recording made now would."""
    for path in sorted(folder.rglob("meta.json")):
        meta = json.loads(path.read_text(encoding="utf-8"))
        if "scenario_toml" in meta:
            meta["scenario_toml"] = scenario_to_toml(scenario, portable=True)
            write_text_atomic(path, json.dumps(meta, indent=2) + "\n")  # (as sensors.recording writes it)


@dataclasses.dataclass(frozen=True)
class Captured:
    """What the later stages take of the capture (from a CaptureResult, or a cache entry's state)."""
    response: RecoveredResponse
    snapshots: list  # [(sweep time s, angle map)]
    probe: np.ndarray  # the captured probe with its holes filled, at the capture's size
    metrics: dict


@dataclasses.dataclass(frozen=True)
class TrackingFigures:
    """What the report takes of the session's tracking (evaluate.tracking.TrackingRun's arrays)."""
    found: np.ndarray
    rot_err_deg: np.ndarray | None
    trans_err_pct: np.ndarray | None

    @property
    def measured(self) -> bool:
        return self.rot_err_deg is not None


class _Stages:
    """Each stage looked up in the cache by its key and reused, or computed and stored; what happened is
    recorded for the manifest."""

    def __init__(self, cache: StageCache, out: Path, step, seconds: dict[str, float]):
        self.cache, self.out, self.step, self.seconds = cache, out, step, seconds
        self.record: dict[str, dict] = {}

    def run(self, name: str, key: str, description: str, compute, save=None, load=None, borrowed=lambda rel: False):
        """(value, {output path: sha256}) of the stage: load(state folder) of the entry where the key matches
        (its outputs copied into the run, those borrowed(path) holds for linked: cache.StageCache.restore), else
        compute() (its outputs: what it wrote into the run), stored with save(value, state folder)."""
        with self.cache.lock(name, key):
            start = time.perf_counter()
            hit = self.cache.lookup(name, key)  # (its files' hashes checked: part of the stage's time)
            self.seconds[name] = round(self.seconds.get(name, 0.0) + time.perf_counter() - start, 2)
            if hit is not None:
                with self.step(name, f"{description} (reused)"):
                    self.cache.restore(hit, self.out, borrowed)
                    value = load(hit.state) if load is not None else None
                self.record[name] = {"status": "reused", "key": key, "from": str(hit.folder)}
                return value, hit.outputs
            before = snapshot(self.out)
            value = compute(description)
            after = snapshot(self.out)
            outputs = [rel for rel, stamp in after.items() if before.get(rel) != stamp]
            entry = self.cache.store(name, key, self.out, outputs,
                                     (lambda folder: save(value, folder)) if save is not None else None)
            self.record[name] = {"status": "computed", "key": key, "from": None,
                                 "stored": str(entry) if entry is not None else None}
            if entry is not None:
                listed = json.loads((entry / ENTRY).read_text(encoding="utf-8"))["files"]
                return value, {rel.removeprefix("files/"): f["sha256"] for rel, f in listed.items() if rel.startswith("files/")}
            return value, _hash_files(self.out, outputs)


def _save_captured(c: Captured, folder: Path) -> None:
    times = [t for t, _ in c.snapshots]
    maps = np.stack([m for _, m in c.snapshots]) if c.snapshots else np.zeros((0, 1, 1, 3), np.float32)
    write_state(folder, {"metrics": c.metrics}, {"response": c.response.linear, "probe": c.probe,
                                                 "snapshot_t": np.asarray(times, np.float64), "snapshots": maps})


def _load_captured(folder: Path) -> Captured:
    data, a = read_state(folder)
    snapshots = [(float(t), m) for t, m in zip(a["snapshot_t"], a["snapshots"])]
    return Captured(RecoveredResponse(a["response"]), snapshots, a["probe"], data["metrics"])


def _save_estimates(e, folder: Path) -> None:
    arrays = {f"{name}/{f.name}": np.asarray(getattr(light, f.name)) for name, light in e.final.items()
              for f in dataclasses.fields(light)}
    write_state(folder, {"figures": e.figures, "absent": e.absent, "final": list(e.final)}, arrays)


def _load_estimates(folder: Path):
    from arsim.estimate.shapes import LightEstimate
    from arsim.run.stages import SweepEstimates

    data, a = read_state(folder)
    final = {}
    for name in data["final"]:
        fields = {f.name: a[f"{name}/{f.name}"] for f in dataclasses.fields(LightEstimate)}
        fields["ambient_intensity"] = float(fields["ambient_intensity"])
        final[name] = LightEstimate(**fields)
    return SweepEstimates(data["figures"], final, data["absent"])


def _save_maps(m: dict, folder: Path) -> None:
    arrays = {f"{kind}/{name}/{s!r}": array for kind in ("maps", "truth_maps") for name, ms in m[kind].items()
              for s, array in ms.maps.items()}
    write_state(folder, {"metrics": m["metrics"], "gl_renderer": m["gl_renderer"],
                         "sources": {kind: {name: ms.source for name, ms in m[kind].items()} for kind in ("maps", "truth_maps")}},
                arrays)


def _load_maps(folder: Path) -> dict:
    from arsim.lighting.mapset import MapSet

    data, a = read_state(folder)
    loaded = {"metrics": data["metrics"], "gl_renderer": data["gl_renderer"]}
    for kind in ("maps", "truth_maps"):
        loaded[kind] = {}
        for name, source in data["sources"][kind].items():
            prefix = f"{kind}/{name}/"
            loaded[kind][name] = MapSet(name, {float(k.removeprefix(prefix)): v for k, v in a.items() if k.startswith(prefix)},
                                        source)
    return loaded


def _save_session(s: dict, folder: Path) -> None:
    t = s["tracking"]
    arrays = {"frames": s["frames"], "found": t.found}
    if t.measured:
        arrays |= {"rot_err_deg": t.rot_err_deg, "trans_err_pct": t.trans_err_pct}
    write_state(folder, {"figures": s["figures"], "estimate_scores": s["estimate_scores"]}, arrays)


def _load_session(folder: Path) -> dict:
    data, a = read_state(folder)
    tracking = TrackingFigures(a["found"], a.get("rot_err_deg"), a.get("trans_err_pct"))
    return {"frames": a["frames"], "tracking": tracking, "figures": data["figures"], "estimate_scores": data["estimate_scores"]}


def _is_image(rel: str) -> bool:
    """A recording's frame image by its path (recording/frames/*.png, recording/burst/*.png, recording/ar/frames/...)."""
    path = Path(rel)
    return path.suffix == ".png" and path.parent.name in ("frames", "burst")


def _recording_frames(folder: Path, hashes: dict[str, str], key: str, content: str, keep: bool,
                      entry: str | None) -> dict:
    """The manifest's account of the recording's frame images: kept, or left out (sensors.recording.leave_out_images)
    with what makes them again byte-identical: `arsim record` of the run's scenario.toml (the recording stage's key
    names the same recording), or the cache entry while it exists."""
    from arsim.sensors.recording import images_digest, leave_out_images, recording_image_paths

    images = {rel: hashes[rel] for rel in recording_image_paths(folder)}
    if keep:
        return {"kept": True, "files": len(images), "bytes": sum((folder / rel).stat().st_size for rel in images),
                "sha256": images_digest(images)}
    totals = leave_out_images(folder, images, {"recording_key": key, "recording_content": content,
                                               "scenario": "../scenario.toml"})
    frames = Path(entry) / "files" / "recording" if entry is not None else None
    return {"kept": False, **totals, "recording_key": key, "recording_content": content,
            "regenerate": "arsim record scenario.toml -o REC (in the run's folder)",
            "cache_entry": str(frames) if frames is not None and frames.is_dir() else None}


def size_text(n: float) -> str:
    """Bytes as people read them: MB below a gigabyte, else GB (powers of ten, as du -h --si)."""
    return f"{n / 1e6:.1f} MB" if n < 1e9 else f"{n / 1e9:.2f} GB"


def disk_summary(manifest: dict, run: Path, entry: bool = False) -> str:
    """What a run takes on disk, and what of its recording it left out and how to make it again (one line); entry:
    also the cache entry that holds the frames, where it still exists."""
    disk, frames = manifest.get("disk"), manifest.get("recording_frames")
    if disk is None:  # (a run written before manifests measured their disk)
        return f"{sum(f['bytes'] for f in manifest['files']) / 1e6:.1f} MB in {len(manifest['files'])} files, manifest.json aside"
    line = f"{size_text(disk['bytes'])} in {disk['files']} files"
    if frames is not None and not frames["kept"]:
        line += (f" (recording frames not kept: {size_text(frames['bytes'])} in {frames['files']} files; regenerate them "
                 f"byte-identical with `arsim record {run / 'scenario.toml'} -o rec`" +
                 (f", or copy them from the run cache's {frames['cache_entry']}"
                  if entry and frames.get("cache_entry") and Path(frames["cache_entry"]).is_dir() else "") + ")")
    return line


def _write_manifest(out: Path, manifest: dict) -> None:
    """manifest.json, its "disk" counting every file of the run listed and the manifest itself."""
    listed = sum(f["bytes"] for f in manifest["files"])
    own = 0
    for _ in range(8):  # (the manifest's size is in it: a few rounds settle its digits)
        manifest["disk"] = {"files": len(manifest["files"]) + 1, "bytes": listed + own}
        text = json_text(manifest)
        if len(text.encode("utf-8")) == own:
            break
        own = len(text.encode("utf-8"))
    write_text_atomic(out / "manifest.json", text)


def kept_frame_bytes() -> int:
    """How much of a recording made by a run is kept decoded for its later stages (core.png.kept_frames): the
    default scenario's 2,400 frames take 2.2 GB; at most a quarter of this machine's memory."""
    try:
        memory = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        memory = 8 * 1024**3
    return min(KEPT_FRAME_BYTES, memory // 4)


def run_scenario(scenario: Scenario, source: str, out: Path, recording: Path | None = None,
                 stage: Callable = quiet_stage, cache: StageCache | None = None, baseline: dict | None = None,
                 keep_recording: bool = False) -> dict:
    """Run every stage into out, each reused from the cache where its key matches (README: The run cache);
    returns the manifest (also written to out/manifest.json). baseline: a baseline run's metrics.json, whose
    figures the report shows beside the run's. The recording made (or reused) is read where it lies while the run
    works; its frame images are left out of out at the end unless keep_recording (README: Run outputs and disk).
    A recording made by the run is also kept decoded in memory while the run lasts (kept_frame_bytes): the
    capture, the estimates and the session read its frames from there instead of inflating each again."""
    with kept_frames(kept_frame_bytes()):
        return _run_stages(scenario, source, out, recording, stage, cache, baseline, keep_recording)


def _run_stages(scenario: Scenario, source: str, out: Path, recording: Path | None, stage: Callable,
                cache: StageCache | None, baseline: dict | None, keep_recording: bool) -> dict:
    """run_scenario's work."""
    from arsim.capture.pipeline import CaptureSettings, recording_scenario
    from arsim.evaluate.compare_methods import maps_figures
    from arsim.evaluate.estimates import estimate_summary, write_estimate_frames
    from arsim.evaluate.flip import flip_worker
    from arsim.evaluate.profile import ProfileRun, write_profile
    from arsim.evaluate.session import lit_by_truth, session_metrics
    from arsim.lighting.bake_output import write_bake
    from arsim.lighting.mapset import MapSet
    from arsim.lighting.methods import MapParameters, bake
    from arsim.render.content import light_objects, scene_objects
    from arsim.render.session import SessionSettings, run_session
    from arsim.run.report import write_report
    from arsim.run.stages import (estimate_lights, estimated_sweep, filled_probe, lit_maps, measured_capture, recorded_pair,
                                  true_probe, with_scenario)
    from arsim.sensors.frames import truth_absent
    from arsim.sensors.recording import record, recording_segments

    cache = cache if cache is not None else StageCache(None)
    seconds: dict[str, float] = {}
    cpu_seconds: dict[str, float] = {}  # the process's CPU time, all threads: above the wall time where work overlaps

    @contextlib.contextmanager
    def step(key: str, description: str):
        """A stage shown by `stage` and timed into the manifest."""
        start, cpu = time.perf_counter(), time.process_time()
        with stage(description) as update:
            yield update
        seconds[key] = round(seconds.get(key, 0.0) + time.perf_counter() - start, 2)
        cpu_seconds[key] = round(cpu_seconds.get(key, 0.0) + time.process_time() - cpu, 2)

    stages = _Stages(cache, out, step, seconds)
    r = scenario.render
    if not scenario.ar.enabled and recording is None:
        raise ArsimError(f"{source}: [ar] enabled = false; a run needs the AR path: set it to true")
    objects = scene_objects(r)  # a mesh that cannot be read fails here, before any work
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "scenario.toml", scenario_to_toml(scenario))

    # 1. The recording: made now (or reused), or one made before (`arsim record`) replayed.
    if recording is None:
        recording_segments(scenario)

        def make_recording(description):
            with step("recording", description) as update:
                record(scenario, out / "recording", progress=lambda f: update(completed=f))

        _, hashes = stages.run("recording", recording_key(scenario), "1/6 recording the sweep and the AR path", make_recording,
                               borrowed=lambda rel: not keep_recording and _is_image(rel))
        if stages.record["recording"]["status"] == "reused":
            _with_scenario_toml(out / "recording", scenario)
        recording = out / "recording"
        hashes = {k.removeprefix("recording/"): v for k, v in hashes.items()}
    else:
        files = [recording] if recording.is_file() else sorted(p for p in recording.rglob("*") if p.is_file())
        hashes = dict(zip([p.relative_to(recording).as_posix() if p != recording else p.name for p in files],
                          sha256_files(files)))
    sweep, ar = recorded_pair(recording)
    recorded = recording_scenario(sweep)  # the sensors as recorded, whatever the scenario given says
    # What of the truth the recording lacks (a real recording: all of it); what needs it is left out, saying why.
    absent = truth_absent(ar) | truth_absent(sweep)
    content = recording_digest(recording if recording.is_dir() else recording.parent, hashes,
                               recorded if "scenario_toml" in sweep.meta else None)

    # 2. The capture, measured against the truth (as far as the recording has one).
    def make_capture(description):
        result, metrics = measured_capture(sweep, CaptureSettings.of(recorded), out / "capture",
                                           lambda d: step("capture", d), description)
        return Captured(result.response, list(result.snapshots), filled_probe(result), metrics)

    keys = stage_keys(scenario, source, content, objects)
    if baseline is not None:  # (the report shows its figures: another report)
        keys["report"] = key_of("report", {"report": keys["report"], "baseline": baseline})
    captured, _ = stages.run("capture", keys["capture"], "2/6 capturing the light probe", make_capture, _save_captured,
                             _load_captured)

    # 3. The light estimates over the sweep (the truth's, the capture's as it grew, each frame's alone), scored.
    def make_estimates(description):
        with step("estimates", description) as update:
            (out / "estimates").mkdir(exist_ok=True)
            # (its frames' progress shown as this step's)
            return estimated_sweep(sweep, out / "estimates", result=captured, stage=lambda d: contextlib.nullcontext(update))

    estimates, _ = stages.run("estimates", keys["estimates"], "3/6 estimating the light as phones report them", make_estimates,
                              _save_estimates, _load_estimates)

    # 4. The maps of every method named, from the captured probe; each measured against the same method's
    # maps of the true environment (what the capture costs) and the true environment's accurate maps, where known.
    probe = to_layout(captured.probe, "anglemap", r.map_size)
    truth = true_probe(sweep, r.map_size)
    needed, methods, exponents = maps_plan(objects, r)
    inside = anglemap_disk_mask(r.map_size)

    def make_maps(description):
        maps, truth_maps, map_metrics = {}, {}, {}
        with step("maps", description) as update:
            params = MapParameters()
            # accurate and bounds on the GL path: NumPy's float64 sums take half a minute at 128².
            gl = create_gl_context()
            gl_renderer = gl.info["GL_RENDERER"]  # (for the manifest: the context is released after the maps)
            reference = bake(truth, exponents, "accurate", params, gl=gl).maps if truth is not None else None
            for k, name in enumerate(methods):
                baked = bake(probe, exponents, name, params, gl=gl)
                (out / "maps" / name).mkdir(parents=True, exist_ok=True)
                write_bake(out / "maps" / name, exponents, name, params, baked, "capture/env.exr")
                maps[name] = MapSet.of(name, exponents, baked.maps, "capture/env.exr")
                update(completed=(k + 1) / len(methods))
                if truth is None:  # (nothing to measure the maps against: metrics.json's "truth" says why)
                    map_metrics[name] = {"seconds": baked.seconds_total}
                    continue
                true_maps = reference if name == "accurate" else bake(truth, exponents, name, params, gl=gl).maps
                truth_maps[name] = MapSet.of(name, exponents, true_maps, "truth")
                map_metrics[name] = {
                    "seconds": baked.seconds_total,
                    "per_exponent": {f"{s:g}": {
                        "error_vs_truth_same_method_pct": map_error(true_maps[e][inside], baked.maps[e][inside]).mean_percent,
                        "error_vs_truth_accurate_pct": map_error(reference[e][inside], baked.maps[e][inside]).mean_percent,
                        "method_error_on_truth_pct": map_error(reference[e][inside], true_maps[e][inside]).mean_percent,
                    } for e, s in enumerate(exponents)}}
            gl.release()
            maps_figures(maps, truth_maps, out / "maps")
        return {"maps": maps, "truth_maps": truth_maps, "metrics": map_metrics, "gl_renderer": gl_renderer}

    baked, _ = stages.run("maps", keys["maps"], f"4/6 baking the maps ({', '.join(methods)})", make_maps, _save_maps, _load_maps)
    maps = baked["maps"]

    # 5. The AR session over the AR path (the objects also lit by each light estimate at the frames shown),
    # its render-loop profile, and the frames lit by each estimate.
    tracked_as: dict = {}  # (the session's tracking: reused or computed, for the manifest)
    lit_as: dict = {}  # (the estimates' maps: reused or computed, likewise)

    def make_session(description):
        session_settings = with_scenario(SessionSettings(r.method, r.key, r.white, r.log_average, overlay=r.overlay,
                                                         flip_every=r.flip_every), scenario,
                                         [light for _, light in captured.snapshots])
        tracked_as["key"] = tracking_key(scenario, keys["capture"], session_settings.every)
        hit = cache.lookup("tracking", tracked_as["key"])
        tracked_as["status"] = "reused" if hit is not None else "computed"
        lit_as["key"] = lit_maps_key(keys["estimates"], needed, r.map_size)
        lit_hit = cache.lookup("lit_maps", lit_as["key"])
        lit_as["status"] = "reused" if lit_hit is not None else "computed"
        profiled = None

        def write_session_profile(records):  # (while the FLIP worker finishes the scores)
            nonlocal profiled
            profiled = ProfileRun("AR session", r.method, scenario.profile.budget_ms, records)
            (out / "profile").mkdir(exist_ok=True)
            write_profile([profiled], out / "profile")

        with step("session", description) as update, flip_worker() as flip:
            if lit_hit is not None:
                estimate_maps = _load_lit_maps(lit_hit.state)
            else:
                estimate_maps = lit_maps(estimates.final, needed, r.map_size)
                cache.store("lit_maps", lit_as["key"], out, [], lambda folder: _save_lit_maps(estimate_maps, folder))
            session = run_session(ar, captured.response.linear[:, 1], maps, baked["truth_maps"] if truth is not None else None,
                                  out, light_objects(objects, probe), flip.score, session_settings,
                                  truth_objects=light_objects(objects, truth) if truth is not None else None,
                                  progress=lambda f: update(completed=f),
                                  estimates=estimate_lights(estimates.final, needed, objects, r.map_size, estimate_maps),
                                  tracked=_load_tracked(hit.state) if hit is not None else None, error_map=flip.error_map,
                                  after_loop=write_session_profile, settle=flip.settle)
            if hit is None:
                cache.store("tracking", tracked_as["key"], out, [], lambda folder: _save_tracked(session.tracked(), folder))
            write_estimate_frames(session.estimate_frames, out / "estimates" / "frames")
            tracking, figures = session_metrics(ar, session)
            figures |= {"budget_ms": profiled.budget_ms, "within_budget_pct": profiled.summary()["within_budget_pct"]}
            if truth is not None and lit_by_truth(maps, baked["truth_maps"]):
                figures["lit_by_truth"] = True  # (the FLIP is 0 by construction: the report says so)
        return {"frames": np.asarray(session.frames), "figures": figures, "estimate_scores": session.estimate_scores,
                "tracking": TrackingFigures(tracking.found, tracking.rot_err_deg, tracking.trans_err_pct)}

    session, _ = stages.run("session", keys["session"], "5/6 rendering the AR session", make_session, _save_session, _load_session)
    if tracked_as:  # (the session computed: its tracking reused from a session of other [render] settings, or done now)
        stages.record["session"]["tracking"] = tracked_as
        stages.record["session"]["lit_maps"] = lit_as

    # 6. Metrics, report and manifest.
    metrics = {"capture": {k: v for k, v in captured.metrics.items() if not isinstance(v, (list, dict)) or k == "warnings"},
               "estimates": estimate_summary(estimates.figures, session["estimate_scores"]),
               "maps": baked["metrics"], "session": {k: v for k, v in session["figures"].items() if k != "truth"}}
    if absent:  # (every stage's figures that need it are left out)
        metrics["truth"] = absent

    def make_report(description):
        with step("report", description):
            write_text_atomic(out / "metrics.json", json_text(metrics))
            write_report(out, scenario, source, metrics, session["tracking"], session["frames"], maps,
                         baked["truth_maps"] if truth is not None else None, baseline)

    stages.run("report", keys["report"], "6/6 writing the report", make_report)
    frames = None  # (a replayed recording lies outside the run: nothing of it to keep or leave out)
    if recording == out / "recording":
        made = stages.record["recording"]
        frames = _recording_frames(recording, hashes, made["key"], content, keep_recording, made["from"] or made.get("stored"))
    for name, s in stages.record.items():
        s["seconds"] = seconds.get(name, 0.0)
        s["cpu_seconds"] = cpu_seconds.get(name, 0.0)
    manifest = {
        "scenario": {"source": source, "name": scenario.run.name, "resolved": "scenario.toml"},
        "seed": scenario.run.seed,
        "recording": str(recording) if recording != out / "recording" else "recording",
        "versions": versions(baked["gl_renderer"]),
        "seconds_per_stage": seconds,
        "cpu_seconds_per_stage": cpu_seconds,
        "stages": stages.record,
        "cache": str(cache.root) if cache.root is not None else None,
        "metrics": metrics,
        "recording_frames": frames,
        "disk": None,  # (_write_manifest)
        "files": _files_under(out, FILE_ROLES),
    }
    _write_manifest(out, manifest)
    return manifest


def check_run(out: Path) -> dict:
    """A run directory checked against its manifest: every stage ran and every file listed is there with the
    size it had (a run cut short, moved without some of its files or edited since fails). Returns the
    manifest; raises ArsimError naming the first thing wrong."""
    path = out / "manifest.json"
    if not path.is_file():
        raise ArsimError(f"{out}: no manifest.json; not a finished run directory (make one with `arsim run -o DIR`)")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
        files, seconds, metrics = manifest["files"], manifest["seconds_per_stage"], manifest["metrics"]
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as exc:
        raise ArsimError(f"{path}: not a manifest arsim wrote ({type(exc).__name__}: {exc}); run the scenario again") from None
    # a replayed recording (`--recording`) is not recorded again
    expected = [s for s in STAGES if s != "recording" or manifest.get("recording") == "recording"]
    missing_stages = [s for s in expected if s not in seconds]
    if missing_stages:
        raise ArsimError(f"{path}: the stage {missing_stages[0]} never finished; run the scenario again")
    missing_metrics = [k for k in ("capture", "maps", "session") if not metrics.get(k)]
    if missing_metrics:
        raise ArsimError(f"{path}: no {missing_metrics[0]} metrics; run the scenario again")
    listed = {f["path"] for f in files}
    for required in ("scenario.toml", "metrics.json", "capture/env.exr", "session.mp4", "report/index.html"):
        if required not in listed:
            raise ArsimError(f"{path}: lists no {required}; run the scenario again")
    for f in files:
        if f["path"] == "manifest.json":  # (listed by runs into a folder that held an earlier run's)
            continue
        p = out / f["path"]
        if not p.is_file():
            raise ArsimError(f"{out}: {f['path']} is missing ({len(files)} files listed in manifest.json); "
                             "copy the whole run directory, or run the scenario again")
        if p.stat().st_size != f["bytes"]:
            raise ArsimError(f"{out}: {f['path']} has {p.stat().st_size} bytes, manifest.json says {f['bytes']}: "
                             "changed since the run; run the scenario again")
    return manifest
