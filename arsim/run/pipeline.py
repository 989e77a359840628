"""`arsim run`: a scenario end to end into one run directory (README: Runs end to end): the recording (or a
recording replayed), the captured probe against the truth, the maps of every method the scenario names
baked from the probe, the AR session's frames, its render-loop profile, the metrics of every stage, the
report and manifest.json.

Stages take a `stage(description)` context manager that yields update(fraction): the command line
shows it as a progress bar naming the stage.
"""

from __future__ import annotations

import contextlib
import json
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
from arsim.core.progress import quiet_stage
from arsim.evaluate.metrics import map_error
from arsim.scenario.loader import scenario_to_toml
from arsim.scenario.sections import Scenario

STAGES = ("recording", "capture", "estimates", "maps", "session", "report")


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


def run_scenario(scenario: Scenario, source: str, out: Path, recording: Path | None = None,
                 stage: Callable = quiet_stage) -> dict:
    """Run every stage into out; returns the manifest (also written to out/manifest.json)."""
    from arsim.capture.pipeline import CaptureSettings, recording_scenario
    from arsim.evaluate.diff import masked_flip
    from arsim.evaluate.estimates import estimate_summary, write_estimate_frames
    from arsim.evaluate.profile import ProfileRun, write_profile
    from arsim.evaluate.session import session_metrics
    from arsim.lighting.bake_output import write_bake
    from arsim.lighting.mapset import MapSet
    from arsim.lighting.methods import MapParameters, bake
    from arsim.render.content import light_objects, scene_objects
    from arsim.render.session import SessionSettings, maps_needed, run_session
    from arsim.run.report import write_report
    from arsim.run.stages import (estimate_lights, estimated_sweep, measured_capture, recorded_pair, session_probe, true_probe,
                                  with_scenario)
    from arsim.sensors.frames import truth_absent
    from arsim.sensors.recording import record, recording_segments

    seconds: dict[str, float] = {}

    @contextlib.contextmanager
    def step(key: str, description: str):
        """A stage shown by `stage` and timed into the manifest."""
        start = time.perf_counter()
        with stage(description) as update:
            yield update
        seconds[key] = round(time.perf_counter() - start, 2)

    r = scenario.render
    if not scenario.ar.enabled and recording is None:
        raise ArsimError(f"{source}: [ar] enabled = false; a run needs the AR path: set it to true")
    objects = scene_objects(r)  # a mesh that cannot be read fails here, before any work
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "scenario.toml", scenario_to_toml(scenario))

    # 1. The recording: made now, or one made before (`arsim record`) replayed.
    if recording is None:
        recording_segments(scenario)
        with step("recording", "1/6 recording the sweep and the AR path") as update:
            record(scenario, out / "recording", progress=lambda f: update(completed=f))
        recording = out / "recording"
    sweep, ar = recorded_pair(recording)
    recorded = recording_scenario(sweep)  # the sensors as recorded, whatever the scenario given says
    # What of the truth the recording lacks (a real recording: all of it); what needs it is left out, saying why.
    absent = truth_absent(ar) | truth_absent(sweep)

    # 2. The capture, measured against the truth (as far as the recording has one).
    result, capture_metrics = measured_capture(sweep, CaptureSettings.of(recorded), out / "capture",
                                               lambda description: step("capture", description),
                                               "2/6 capturing the light probe")

    # 3. The light estimates over the sweep (the truth's, the capture's as it grew, each frame's alone), scored.
    with step("estimates", "3/6 estimating the light as phones report it"):
        (out / "estimates").mkdir(exist_ok=True)
        estimates = estimated_sweep(sweep, out / "estimates", result=result)

    # 4. The maps of every method named, from the captured probe; each measured against the same method's
    # maps of the true environment (what the capture costs) and the true environment's accurate maps, where known.
    probe = session_probe(result, r.map_size)
    truth = true_probe(sweep, r.map_size)
    needed = maps_needed(objects, r.method)
    exponents = sorted({s for ss in needed.values() for s in ss})
    methods = list(dict.fromkeys([*needed, *r.methods]))
    maps, truth_maps, map_metrics = {}, {}, {}
    inside = anglemap_disk_mask(r.map_size)
    with step("maps", f"4/6 baking the maps ({', '.join(methods)})") as update:
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

    # 5. The AR session over the AR path (the objects also lit by each light estimate at the frames shown),
    # and its render-loop profile.
    session_settings = with_scenario(SessionSettings(r.method, r.key, r.white, r.log_average, overlay=r.overlay,
                                                     flip_every=r.flip_every), scenario, [light for _, light in result.snapshots])
    with step("session", "5/6 rendering the AR session") as update:
        session = run_session(ar, result.response.linear[:, 1], maps, truth_maps if truth is not None else None, out,
                              light_objects(objects, probe), masked_flip, session_settings,
                              truth_objects=light_objects(objects, truth) if truth is not None else None,
                              progress=lambda f: update(completed=f),
                              estimates=estimate_lights(estimates.final, needed, objects, r.map_size))
    (out / "profile").mkdir(exist_ok=True)
    write_profile([ProfileRun("AR session", r.method, scenario.profile.budget_ms, session.records)], out / "profile")

    # 6. Metrics, report and manifest.
    tracking, session_figures = session_metrics(ar, session)
    metrics = {"capture": {k: v for k, v in capture_metrics.items() if not isinstance(v, (list, dict)) or k == "warnings"},
               "estimates": estimate_summary(estimates.figures, session.estimate_scores),
               "maps": map_metrics, "session": {k: v for k, v in session_figures.items() if k != "truth"}}
    if absent:  # (every stage's figures that need it are left out)
        metrics["truth"] = absent
    write_text_atomic(out / "metrics.json", json_text(metrics))
    with step("report", "6/6 writing the report") as update:
        write_estimate_frames(session.estimate_frames, out / "estimates" / "frames")
        write_report(out, scenario, source, metrics, tracking, session.frames, maps)
    manifest = {
        "scenario": {"source": source, "name": scenario.run.name, "resolved": "scenario.toml"},
        "seed": scenario.run.seed,
        "recording": str(recording) if recording != out / "recording" else "recording",
        "versions": versions(gl_renderer),
        "seconds_per_stage": seconds,
        "metrics": metrics,
        "files": _files_under(out, FILE_ROLES),
    }
    write_text_atomic(out / "manifest.json", json_text(manifest))
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
