"""The stages composed into the steps the commands run: a recording with its plots, a capture measured
against the truth, an AR session's inputs, the AR session rendered and measured, the render loop profiled
while it bakes. `arsim run` (pipeline.py) chains them all; `arsim record`, `capture`, `render` and `profile`
call one each; the command line only parses, calls and prints.

`stage(description)` is a context manager yielding update(completed=None, description=None): the commands
pass core.progress's (a bar on a terminal, plain lines elsewhere); the default, quiet_stage, shows nothing.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from arsim.capture.accumulate import filled
from arsim.capture.pipeline import CaptureResult, CaptureSettings, capture, recording_response, recording_scenario
from arsim.capture.response import response_error
from arsim.core.errors import ArsimError
from arsim.core.files import json_text, write_text_atomic
from arsim.core.progress import quiet_stage
from arsim.core.resample import to_layout
from arsim.evaluate.capture_report import write_capture
from arsim.evaluate.flip import flip_worker
from arsim.evaluate.profile import ProfileRun, write_profile
from arsim.evaluate.recording_plots import plot_ar_path, plot_recording
from arsim.evaluate.session import lit_by_truth, session_metrics
from arsim.render.baking import BakeSettings
from arsim.render.content import light_objects, scene_objects
from arsim.render.session import SessionSettings, check_maps, maps_needed, run_profile, run_session, session_maps
from arsim.scenario import Scenario
from arsim.scenario.environment import load_environment
from arsim.sensors.camera import ResponseCurve, SensorSettings
from arsim.sensors.frames import true_environment, truth_absent
from arsim.sensors.recording import Recording, RecordSummary, load_recording, record

Stage = Callable[[str], contextlib.AbstractContextManager]


def true_response(scenario: Scenario) -> np.ndarray:
    """The camera's true inverse response (256,), what the capture's calibration is measured against."""
    cam = scenario.device.camera
    return ResponseCurve(cam.response, cam.gamma, cam.contrast).decode(np.arange(256))


@dataclasses.dataclass(frozen=True)
class PlottedRecording:
    """A recording written with its plots: what was recorded, the share of the sphere its sweep saw,
    and the share of AR frames with the tag in view (None without an AR path)."""

    summary: RecordSummary
    coverage: float
    tag_in_view: float | None


def recorded(scenario: Scenario, out: Path, stage: Stage = quiet_stage,
             description: str = "recording the capture sweep and the AR path", compact: bool = False) -> PlottedRecording:
    """The scenario recorded into out (the sweep; its AR path into out/ar), with the plots in out/plots; compact:
    the frames in lossless videos (sensors.recording.record)."""
    with stage(description) as update:
        summary = record(scenario, out, progress=lambda f: update(completed=f), compact=compact)
    plots = plot_recording(load_recording(out), out / "plots")
    tag = None
    if summary.ar_frames:
        tag = plot_ar_path(load_recording(out / "ar"), out / "plots" / "ar_path.png")["tag_in_view"]
    return PlottedRecording(summary, plots["coverage"], tag)


def true_probe(rec: Recording, size: int) -> np.ndarray | None:
    """The true environment a recording saw as a size² angle map; None where it is unknown (no scenario in
    its meta.json: sensors.frames.truth_absent)."""
    section = true_environment(rec)
    return None if section is None else load_environment(dataclasses.replace(section, probe_size=size))


def measured_capture(rec: Recording, settings: CaptureSettings, out: Path, stage: Stage = quiet_stage,
                     description: str = "capturing") -> tuple[CaptureResult, dict]:
    """The capture of a recording's sweep, measured against the truth as far as the recording has one, written
    into out (env.exr, metrics.json, plots, TUM trajectories); returns the result and its metrics."""
    scenario = recording_scenario(rec)  # the sensors as recorded
    with stage(description) as update:  # (its files and plots part of the stage: 1.5 s of a default capture's)
        result = capture(rec, settings, progress=lambda f, c: update(
            completed=f, description=f"{description}: {100 * c:.1f} % covered"))
        truth = true_probe(rec, settings.size)
        error = response_error(result.response, true_response(scenario)) if truth is not None else None
        return result, write_capture(result, truth, error, out, rec.meta["camera"]["fps"], truth_absent(rec))


def captured_sweep(scenario: Scenario, out: Path, size: int | None = None, align_every: int | None = None,
                   stage: Stage = quiet_stage) -> tuple[CaptureResult, dict]:
    """The scenario's sweep alone (no AR path) recorded into out/recording, then captured and measured as
    measured_capture does; size and align_every override [capture] where given."""
    rec = recorded_sweep(scenario, out / "recording", stage)
    return measured_capture(rec, CaptureSettings.of(recording_scenario(rec), size, align_every), out, stage)


def recorded_sweep(scenario: Scenario, folder: Path, stage: Stage = quiet_stage) -> Recording:
    """The scenario's sweep alone (no AR path) recorded into folder, loaded."""
    sweep = dataclasses.replace(scenario, ar=dataclasses.replace(scenario.ar, enabled=False))
    with stage("recording the capture sweep") as update:
        record(sweep, folder, progress=lambda f: update(completed=f))
    return load_recording(folder)


@dataclasses.dataclass(frozen=True)
class SweepEstimates:
    figures: dict  # scores.json's content
    final: dict  # estimator -> its LightEstimate at the sweep's end (what the app carries into the AR session), truth's too
    absent: str | None = None  # why there are no scores (figures empty): the true environment is unknown


def estimated_sweep(rec: Recording, out: Path, given: list[dict] | None = None, stage: Stage = quiet_stage,
                    result: CaptureResult | None = None) -> SweepEstimates:
    """Light estimates over a recording's sweep (README: Light estimation): the truth's, the capture's as its
    probe grows, each frame's alone, and `given` (a user's, read_estimates'); estimates.jsonl, scores.json,
    scores.png, spheres.png and platforms/ (the last frame's estimates in ARCore's, ARKit's and WebXR's
    structures) into out. result: the sweep's capture where it was made before (else it is made here)."""
    from arsim.estimate.series import estimate_lines, line_estimate
    from arsim.capture.pipeline import fused_camera_orientations
    from arsim.estimate.platforms import PLATFORMS
    from arsim.estimate.shapes import estimate_light
    from arsim.evaluate.estimates import plot_scores, scores, sphere_figures

    if result is None:
        with stage("capturing the sweep (the capture estimate's probe)") as update:
            result = capture(rec, CaptureSettings.of(recording_scenario(rec)), progress=lambda f, c: update(completed=f))
    truth = true_probe(rec, ESTIMATE_TRUTH_SIZE)  # (None: unknown; the estimates are made, not scored)
    with stage("estimating the light from each frame alone") as update:
        single = single_frame_estimates(rec, result.response, lambda f: update(completed=f))
    with stage("estimating the light"):
        views = fused_camera_orientations(rec).as_matrix()  # (the phone's camera frame: what its estimates are in)
        lines = estimate_lines(np.array([f["t_ns"] for f in rec.frames]), truth, result.snapshots, given, single, views)
        write_text_atomic(out / "estimates.jsonl", "".join(json_text(line, indent=None) for line in lines))
        figures = scores(lines) if truth is not None else {}
        # the truth's own estimate, where the truth is known: what a perfect estimator reports, the shapes' own limit
        final = {"truth": estimate_light(truth)} if truth is not None else {}
        if result.snapshots:
            final["capture"] = estimate_light(result.snapshots[-1][1])
        final["single"] = single[-1]
        figures = sphere_figures(figures, truth, final, lines[-1].get("file"), out / "spheres.png")
        (out / "platforms").mkdir(exist_ok=True)
        for name, e in final.items():  # the sweep's last frame, per platform
            for platform, shape in PLATFORMS.items():
                write_text_atomic(out / "platforms" / f"{name}_{platform}.json", json_text(shape(e)))
        if truth is not None:
            write_text_atomic(out / "scores.json", json_text(figures))
            plot_scores(lines, out / "scores.png")
        else:  # (scores.json says why it holds none)
            write_text_atomic(out / "scores.json", json_text({"truth": truth_absent(rec)["scenario"]}))
    if given:
        final["file"] = line_estimate(given[-1])
    return SweepEstimates(figures, final, None if truth is not None else truth_absent(rec)["scenario"])


def estimate_lights(final: dict, needed: dict[str, list[float]], objects: list, map_size: int,
                    maps: dict[str, dict] | None = None) -> dict:
    """Per estimator, the maps and objects its estimate lights the AR session's objects with (estimate.lit:
    the maps from its SH, main light and cubemap; what is baked from a light, from its cubemap). maps:
    lit_maps' (made before), else made here."""
    from arsim.estimate.lit import environment

    maps = lit_maps(final, needed, map_size) if maps is None else maps
    return {name: (maps[name], light_objects(objects, environment(e, map_size))) for name, e in final.items()}


def lit_maps(final: dict, needed: dict[str, list[float]], map_size: int) -> dict[str, dict]:
    """Per estimator, its maps per map method the objects need (estimate.lit.estimate_maps)."""
    from arsim.estimate.lit import estimate_maps

    return {name: estimate_maps(e, needed, map_size, f"{name} estimate") for name, e in final.items()}


def single_frame_estimates(rec: Recording, response, progress=lambda fraction: None) -> list:
    """Each frame's estimate from its image alone (estimate/single_frame.py), with the phone's fused
    orientation and the recovered response over the frame's exposure. Only the metered frames are
    estimated: the sweep's bracketed ones (darker or brighter for the response's calibration and the
    highlights) are not what a phone's preview shows its light estimation; they keep the estimate of the
    metered frame before them."""
    from arsim.capture.pipeline import exposure_scales, fused_camera_orientations
    from arsim.core.png import read_frames
    from arsim.estimate.single_frame import SingleFrameEstimator
    from arsim.sensors.frames import recording_camera

    estimator = SingleFrameEstimator(recording_camera(rec))
    scenario = recording_scenario(rec)
    scales = exposure_scales(rec, SensorSettings.of(scenario.device.camera))
    bracket = scenario.capture.bracket_ev  # frame k was taken at bracket[k % len]; 0: metered
    views = fused_camera_orientations(rec).as_matrix()
    metered = [k for k in range(len(rec.frames)) if bracket[k % len(bracket)] == 0 or k == 0]
    estimated = set(metered)
    frames = read_frames(rec.folder / rec.frames[k]["file"] for k in metered)  # (decoded ahead, in this order)
    out = []
    for k in range(len(rec.frames)):
        if k not in estimated:
            out.append(out[-1])
            continue
        out.append(estimator.estimate(next(frames), response.linear / scales[k], views[k]))
        if k % 50 == 0:
            progress(k / len(rec.frames))
    return out


ESTIMATE_TRUTH_SIZE = 512  # the true environment's angle map the truth's estimate is taken from


def filled_probe(result: CaptureResult) -> np.ndarray:
    """The captured probe with its holes filled from their surroundings, at the capture's size."""
    acc = result.accumulator
    return filled(acc.probe(), acc.covered())


def session_probe(result: CaptureResult, map_size: int) -> np.ndarray:
    """The captured probe as the maps take it: holes filled from their surroundings, map_size²."""
    return to_layout(filled_probe(result), "anglemap", map_size)


def session_inputs(scenario: Scenario, out: Path, probe: np.ndarray | None, map_size: int, capture_probe: bool = True,
                   stage: Stage = quiet_stage, recording: tuple[Recording, Recording] | None = None):
    """What an AR session needs: the scenario recorded into out/recording (or the sweep and AR path of
    `recording`, made before, in any layout: recorded_pair), its AR part, the light probe (`probe` where given,
    else captured from the sweep; None when not wanted) as a map_size angle map, the camera's response (from
    the capture, or from the sweep's calibration or burst), the probe as it grew (the capture's snapshots;
    empty where none was captured), and the sweep's recording."""
    if recording is None:
        with stage("recording the sweep and the AR path") as update:
            record(scenario, out / "recording", progress=lambda f: update(completed=f))
        sweep, ar = load_recording(out / "recording"), load_recording(out / "recording" / "ar")
        recorded = scenario
    else:
        sweep, ar = recording
        recorded = recording_scenario(sweep)  # the sensors as recorded (its own, or the default's where it names none)
    if probe is None and capture_probe:
        with stage("capturing the light probe") as update:
            result = capture(sweep, CaptureSettings.of(recorded), progress=lambda f, c: update(completed=f))
        return ar, session_probe(result, map_size), result.response, [light for _, light in result.snapshots], sweep
    return ar, probe, recording_response(sweep, SensorSettings.of(recorded.device.camera)), [], sweep


def with_scenario(settings: SessionSettings, scenario: Scenario, snapshots: list) -> SessionSettings:
    """The session's settings with what the scenario says of the app: its tag detector, and the growing
    probe to replay where [render] prt_light = "growing"."""
    settings = dataclasses.replace(settings, detector=scenario.ar.detector, fusion=scenario.ar.fusion)
    if scenario.render.prt_light != "growing":
        return settings
    if not snapshots:
        raise ArsimError('[render] prt_light = "growing" replays the probe as the capture grew; give no --env '
                         '(a probe given whole did not grow), or set prt_light = "final"')
    return dataclasses.replace(settings, lights=tuple(snapshots))


def render_session(scenario: Scenario, out: Path, settings: SessionSettings, map_size: int, probe: np.ndarray | None = None,
                   maps: dict | None = None, source: str = "captured", stage: Stage = quiet_stage,
                   objects: list | None = None, recording: tuple[Recording, Recording] | None = None) -> dict:
    """The AR session of a scenario into out: recorded (or `recording`'s sweep and AR path, made before,
    replayed), the probe captured (or `probe`), the objects (scene_objects of the scenario, unless given) lit
    by maps from it (or by `maps` baked before), each frame scored against its truth frame where the true
    environment is known; metrics.json written; returns the metrics."""
    objects = scene_objects(scenario.render, scenario.ar.table_albedo) if objects is None else objects
    needed = maps_needed(objects, settings.method)
    if maps is not None:
        check_maps(maps, needed)
    ar, probe, response, growing, sweep = session_inputs(scenario, out, probe, map_size, capture_probe=maps is None,
                                                         stage=stage, recording=recording)
    # the true environment: the scenario's, or a replayed recording's own (None where it does not know it)
    truth = (load_environment(dataclasses.replace(scenario.environment, probe_size=map_size)) if recording is None
             else true_probe(sweep, map_size))
    settings = with_scenario(settings, scenario, growing)
    with stage(f"computing the maps ({', '.join(needed)})"):
        maps = maps if maps is not None else session_maps(probe, needed, source)
        truth_maps = session_maps(truth, needed, "truth") if truth is not None else None
    with stage(f"rendering the AR session ({', '.join(needed)} maps)") as update, flip_worker() as flip:
        session = run_session(ar, response.linear[:, 1], maps, truth_maps, out, light_objects(objects, probe), flip.score,
                              settings, truth_objects=light_objects(objects, truth) if truth is not None else None,
                              progress=lambda f: update(completed=f), settle=flip.settle)
    metrics = session_metrics(ar, session)[1] | {"method": settings.method, "methods": needed, "map_size": map_size,
                                                 "log_average": settings.log_average, "probe": source}
    if truth_maps is not None and lit_by_truth(maps, truth_maps):
        metrics["lit_by_truth"] = True  # (the FLIP is 0 by construction, not a result)
    write_text_atomic(out / "metrics.json", json_text(metrics))
    return metrics


def recorded_pair(source: Path) -> tuple[Recording, Recording]:
    """A recording made before, in any layout (README: Recordings in standard layouts), and its AR path."""
    from arsim.sensors.formats import ar_source, open_recording

    sweep = open_recording(source)
    ar = ar_source(source, sweep)
    if ar is None:
        raise ArsimError(f"{source}: the recording has no AR path (its meta names no ar_recording, or ar/ is not a "
                         "recording); the AR session needs one: record a scenario with [ar] enabled = true")
    return sweep, open_recording(ar)


def tumvi_photometric(rec: Recording):
    """The photometric calibration a TUM-VI export carries for an arsim recording: the inverse response as the
    capture calibrates it from the burst (so that a capture of the export uses what a capture of the recording
    does) and the camera's vignette; None for a recording without a burst (the AR path's)."""
    from arsim.capture.pipeline import burst_response
    from arsim.sensors.camera import vignette
    from arsim.sensors.formats.common import Photometric
    from arsim.sensors.frames import recording_camera

    if not rec.burst or "scenario_toml" not in rec.meta:
        return None
    sensor = SensorSettings.of(recording_scenario(rec).device.camera)
    camera = recording_camera(rec)
    return Photometric(255.0 * burst_response(rec, sensor).linear[:, 0],
                       vignette(camera.height, camera.width, sensor.vignetting).astype(np.float32))


def exported_recording(rec: Recording, source: Path, kind: str, out: Path, stage: Stage = quiet_stage) -> list:
    """A recording (any layout, read from source) and its AR path written in EuRoC's, TUM-VI's or a ROS 2 bag's layout into out
    (the AR path into out/ar); TUM-VI's photometric calibration from the burst where the recording has none.
    Returns [(recording, folder)] as written."""
    from arsim.sensors.formats import export_recording

    with stage(f"writing the recording as {kind}"):
        return export_recording(rec, source, kind, out, tumvi_photometric)


def profile_session(scenario: Scenario, out: Path, bakes: Sequence[BakeSettings], budget_ms: float, max_frames: int,
                    map_size: int, probe: np.ndarray | None = None, stage: Stage = quiet_stage,
                    objects: list | None = None) -> list[ProfileRun]:
    """The render loop over a scenario's AR path while step 3 bakes maps tile by tile, once per bake setting
    (tile policy), into out (profile.md, trace.json, timeline.png; frames per run); returns the runs."""
    for b in bakes:
        b.check(map_size)  # a tile that does not divide the maps fails here, before any work
    r = scenario.render
    objects = scene_objects(r, scenario.ar.table_albedo) if objects is None else objects
    ar, probe, response, growing, _ = session_inputs(scenario, out, probe, map_size, stage=stage)
    settings = with_scenario(SessionSettings("mipmap", r.key, r.white, r.log_average, overlay=True), scenario, growing)
    runs, poses = [], {}
    for b in bakes:
        with stage(f"baking {b.method} maps in the loop, tile {b.label}") as update:
            records = run_profile(ar, response.linear[:, 1], probe, objects, b, budget_ms, max_frames,
                                  out / (f"tile_{b.label}" if len(bakes) > 1 else "."), settings, poses=poses,
                                  progress=lambda f: update(completed=f))
        runs.append(ProfileRun(b.label, b.method, budget_ms, records))
    write_profile(runs, out)
    return runs
