"""The arsim command line: parses arguments, calls the stages, prints. No pipeline logic lives here."""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
from pathlib import Path

import numpy as np

from arsim import __version__
from arsim.core.assets import bundled_scenarios
from arsim.core.conventions import is_map_size
from arsim.core.errors import ArsimError
from arsim.core.files import check_output_folder, json_text, staged_folder
from arsim.core.hdr_io import NONFINITE_POLICIES, read_hdr, replace_nonfinite, write_image
from arsim.core.image_stats import image_stats
from arsim.core.progress import progress_bar, progress_mode
from arsim.core.resample import LAYOUTS, detect_layout, to_layout
from arsim.evaluate.compare_methods import DEFAULT_SH_ORDERS, check_request, compare, write_comparison
from arsim.evaluate.diff import DEFAULT_MAX_FLIP, check_max_flip
from arsim.lighting.accurate import MAX_EXPONENT
from arsim.lighting.bake_output import write_bake
from arsim.lighting.methods import DEFAULT_EXPONENTS, LOOP_METHODS, METHODS, MapParameters, bake
from arsim.lighting.sh import WINDOWS
from arsim.scenario import DEFAULT_SCENARIO, load_scenario, scenario_to_toml
from arsim.scenario.loader import scenario_path
from arsim.sensors.formats import FORMATS as RECORDING_FORMATS, detect_format
from arsim.sensors.recording import load_recording, recording_segments

MAX_SIZE = 16384


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage dump) and exit status 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


@contextlib.contextmanager
def _bar(description: str):
    """A stage's progress bar (on a terminal), for the library's stages."""
    with progress_bar(description, 1.0) as update:
        yield update


def _command(sub, name: str, summary: str, example: str) -> argparse.ArgumentParser:
    return sub.add_parser(
        name,
        help=summary,
        description=summary,
        epilog=f"example:\n  {example}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def _size(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"size {text!r} is not an integer") from None
    if not 1 <= value <= MAX_SIZE:
        raise argparse.ArgumentTypeError(f"size {value} is out of range: give 1 to {MAX_SIZE}")
    return value


def _path(text: str) -> Path:
    """An argparse type: a path, refused when the OS could not take it (a NUL byte, an empty string)."""
    if "\x00" in text:
        raise argparse.ArgumentTypeError(f"path {text!r} holds a NUL byte; give a path without one")
    if not text:
        raise argparse.ArgumentTypeError("an empty path; give a file or folder")
    return Path(text)


# --------------------------------------------------------------------------------------------------
# arsim info


def _fmt(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.6g}"


def cmd_info(args: argparse.Namespace) -> int:
    if (args.file / "manifest.json").is_file():
        return _run_info(args)
    if args.file.is_dir() or detect_format(args.file) is not None:  # arsim's, EuRoC's, TUM-VI's, a ROS 2 bag
        return _recording_info(args)
    stats = image_stats(read_hdr(args.file))
    if args.json:
        print(json.dumps({"file": str(args.file), **stats}, indent=2))
        return 0
    kind = "angle map 1:1" if stats["layout"] == "anglemap" else "equirect 2:1"
    rows = [
        ("file", str(args.file)),
        ("size", f"{stats['width']} x {stats['height']} ({kind}, {stats['texels']} texels on the sphere)"),
        ("radiance", f"min {_fmt(stats['min'])}  max {_fmt(stats['max'])}  mean {_fmt(stats['mean'])} (finite texels, all channels)"),
        ("mean RGB", "  ".join(_fmt(v) for v in stats["mean_rgb"]) if stats["mean_rgb"] else "n/a"),
        ("sphere mean", "  ".join(_fmt(v) for v in stats["sphere_mean_rgb"]) + " (RGB, weighted by texel solid angle)"),
        ("bad texels", f"NaN {stats['nan']}  Inf {stats['inf']}  negative {stats['negative']}"),
    ]
    for key, value in rows:
        print(f"{key:<12} {value}")
    return 0


def _run_info(args: argparse.Namespace) -> int:
    from arsim.run.pipeline import check_run, disk_summary

    manifest = check_run(args.file)
    s = manifest["metrics"]["session"]
    summary = {"run": str(args.file), "scenario": manifest["scenario"]["name"], "seed": manifest["seed"],
               "files": len(manifest["files"]), "bytes": sum(f["bytes"] for f in manifest["files"]),
               "seconds_per_stage": manifest["seconds_per_stage"], "frames_total": s["frames_total"],
               "frames_lost": s["frames_lost"], "flip_mean": s.get("flip_mean"), "versions": manifest["versions"],
               "disk": manifest.get("disk"), "recording_frames": manifest.get("recording_frames")}
    if args.json:
        print(json_text(summary), end="")
        return 0
    stages = ", ".join(f"{k} {v:.1f} s" for k, v in summary["seconds_per_stage"].items())
    print(f"run {summary['run']}: scenario {summary['scenario']} (seed {summary['seed']}), complete: "
          f"{summary['files']} files, {summary['bytes'] / 1e6:.1f} MB, as manifest.json lists them")
    print(f"stages     {stages}")
    print(f"disk       {disk_summary(manifest, args.file, entry=True)}")
    print(f"session    {s['frames_total']} frames ({s['frames_lost']} with the tag lost), {_tracking_p95(s)}, "
          + ("frames not scored (the true environment is unknown)" if "flip_mean" not in s else
             "FLIP against the truth frame " + (f"{s['flip_mean']:.4f}" if s["flip_mean"] is not None else "not computed")))
    for why in manifest["metrics"].get("truth", {}).values():
        print(f"truth      {why}")
    return 0


def _recording_info(args: argparse.Namespace) -> int:
    from arsim.sensors.frames import check_frame_pixels, truth_absent

    rec = load_recording(args.file)
    with progress_bar("decoding the frames", 1.0) as update:
        decoded = check_frame_pixels(rec, progress=lambda f: update(completed=f))
    summary = {
        "recording": str(args.file),
        "format": rec.meta["format"],
        "layout": rec.meta.get("source_format", "arsim"),
        "seed": rec.meta["seed"],
        "duration_s": rec.meta["duration_s"],
        "frames": len(rec.frames),
        "camera": rec.meta["camera"],
        "imu_samples": {name: len(stream.t_ns) for name, stream in rec.imu.items()},
        "fusion": rec.meta["fusion"],
        "segment": rec.meta.get("segment", "capture"),
        "frames_decoded": decoded,
        "ground_truth": rec.groundtruth is not None,
        "photometric_calibration": rec.photometric is not None,
        "truth_absent": truth_absent(rec),
    }
    if "table" in rec.meta:
        summary["tag"] = {k: rec.meta["table"][k] for k in ("tag_family", "tag_id", "tag_size_m")}
    if "ar_recording" in rec.meta:
        summary["ar_recording"] = str(Path(args.file) / rec.meta["ar_recording"])
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    cam = summary["camera"]
    print(f"{'recording':<12} {args.file} ({summary['format']}" + (f", read from its {summary['layout']} layout" if summary["layout"] != "arsim" else "")
          + f", seed {summary['seed']})")
    print(f"{'duration':<12} {summary['duration_s']:.1f} s, {summary['frames']} frames of {cam['width']} x {cam['height']} at {cam['fps']:g} fps")
    print(f"{'IMU':<12} " + ", ".join(f"{name} {n}" for name, n in summary["imu_samples"].items()) + " samples")
    print(f"{'fusion':<12} {summary['fusion']}")
    print(f"{'segment':<12} {summary['segment']}" + (f" (the AR path is in {summary['ar_recording']})" if "ar_recording" in summary else ""))
    if "tag" in summary:
        tag = summary["tag"]
        print(f"{'tag':<12} {tag['tag_family']} id {tag['tag_id']}, {1000 * tag['tag_size_m']:g} mm, on the table at the origin")
    absent = summary["truth_absent"]
    print(f"{'truth':<12} " + ("ground-truth poses and the scenario (true environment, camera response)" if not absent else
                               "; ".join(absent.values())))
    return 0


# --------------------------------------------------------------------------------------------------
# arsim record


def cmd_record(args: argparse.Namespace) -> int:
    from arsim.run.stages import recorded

    scenario = load_scenario(args.scenario)
    recording_segments(scenario)  # settings that do not fit together stop here, before any output
    with _output(args, _scenario_file(args.scenario)) as work:
        r = recorded(scenario, work, _bar, compact=args.compact)
    out = args.output
    ar = (f"; AR path: {r.summary.ar_frames} frames in {out / 'ar'}, the tag in view in {100 * r.tag_in_view:.1f} % of them"
          if r.tag_in_view is not None else "")
    print(f"wrote {r.summary.frames} frames and the IMU streams of a {r.summary.duration_s:.0f} s sweep to {out}; "
          f"{100 * r.coverage:.2f} % of the sphere seen; fused yaw error at the end "
          f"{r.summary.final_yaw_error_deg:+.2f} degrees{ar}; plots in {out / 'plots'}")
    return 0


# --------------------------------------------------------------------------------------------------
# arsim capture


def cmd_capture(args: argparse.Namespace) -> int:
    from arsim.capture.pipeline import CaptureSettings, recording_scenario
    from arsim.run.stages import captured_sweep, measured_capture

    source = args.source
    if source is not None and (source.is_dir() or detect_format(source) is not None):
        rec = load_recording(source)  # (any layout: README, Recordings in standard layouts)
        settings = CaptureSettings.of(recording_scenario(rec), args.size, args.align_every)
        with _output(args, source) as work:
            _, metrics = measured_capture(rec, settings, work, _bar)
    else:
        scenario = load_scenario(source)
        recording_segments(scenario)  # settings that do not fit together stop here, before any output
        with _output(args, _scenario_file(source)) as work:
            _, metrics = captured_sweep(scenario, work, args.size, args.align_every, _bar)
    out = args.output
    for warning in metrics["warnings"]:
        print(f"warning: {warning}", file=sys.stderr)
    refined = (f"refined ({metrics['keyframes']} keyframes, {metrics['loop_closures']} matched pairs, "
               f"{metrics['direct_pairs']} of them aligned directly)" if metrics["refined"] else "corrected")
    if "orientation_rms_deg_corrected" in metrics:
        orientation = (f"orientation error RMS {metrics['orientation_rms_deg_corrected']:.2f} degrees {refined}, "
                       + (f"{metrics['orientation_rms_deg_online']:.2f} online, " if metrics["refined"] else "")
                       + f"{metrics['orientation_rms_deg_uncorrected']:.2f} uncorrected (RPE over "
                       f"{metrics['rpe_delta_frames']} frames {metrics['rpe_rot_rmse_deg_corrected']:.3f} degrees RMS)")
    else:
        orientation = f"orientations {refined}, not measured (no ground truth)"
    irradiance = (f"irradiance map error {metrics['irradiance_mean_err_pct']:.2f} %" if "irradiance_mean_err_pct" in metrics
                  else "probe not measured (the true environment is unknown)")
    print(f"captured {metrics['frames']} frames at {metrics['frames_per_second']:.1f} frames/s into {out / 'env.exr'}: "
          f"{metrics['coverage_pct']:.2f} % covered; {orientation}; {irradiance}; metrics in {out / 'metrics.json'}, "
          f"trajectories in {out}/trajectory_*.tum")
    for why in metrics.get("truth", {}).values():
        print(f"note: the truth is {why}")
    return 0


# arsim export


def _export_recording(args: argparse.Namespace) -> int:
    """A recording (and its AR path) in EuRoC's, TUM-VI's or a ROS 2 bag's layout."""
    from arsim.run.stages import exported_recording
    from arsim.sensors.formats import open_recording

    layout = args.format[0]
    rec = open_recording(args.input)  # a recording that cannot be read fails here, before any output
    with _output(args, args.input) as work:
        written = exported_recording(rec, args.input, layout, work, _bar)
    out = args.output
    ar = f", the AR path's {len(written[1][0].frames)} in {out / 'ar'}" if len(written) > 1 else ""
    calibrated = layout == "tumvi" and (out / "dso" / "cam0" / "pcalib.txt").is_file()
    print(f"wrote {len(written[0][0].frames)} frames as {layout} to {out}{ar}"
          + ("; the photometric calibration in dso/cam0" if calibrated else ""))
    return 0


# arsim estimate


def cmd_estimate(args: argparse.Namespace) -> int:
    from arsim.estimate.series import read_estimates
    from arsim.run.stages import estimated_sweep, recorded_sweep
    from arsim.sensors.frames import NO_SCENARIO

    source = args.source
    given = read_estimates(args.file, 10**9) if args.file is not None else None  # bad lines fail here, first
    if source is not None and (source.is_dir() or detect_format(source) is not None):
        rec = load_recording(source)
        if given is not None:
            read_estimates(args.file, len(rec.frames))  # (and frames beyond the recording's)
        with _output(args, source, args.file) as work:
            figures = estimated_sweep(rec, work, given, _bar).figures
    else:
        scenario = load_scenario(source)
        recording_segments(scenario)
        with _output(args, _scenario_file(source), args.file) as work:
            rec = recorded_sweep(scenario, work / "recording", _bar)
            if given is not None:
                read_estimates(args.file, len(rec.frames))
            figures = estimated_sweep(rec, work, given, _bar).figures
    if not figures:
        print(f"no scores: the truth is {NO_SCENARIO}")
    for name, f in figures.items():
        diffuse = f["spheres"]["diffuse"]["rmse"] if "spheres" in f else None
        sphere = "" if diffuse is None else f"; diffuse sphere RMSE {100 * diffuse:.1f} %"
        if "final" not in f:  # (the truth's own estimate: scored by its spheres only)
            print(f"{name:<8} own estimate{sphere}")
            continue
        final = f["final"]
        print(f"{name:<8} at the end: SH error {100 * final['sh_error']:.2f} %, main light {final['main_light_error_deg']:.2f} "
              f"degrees off, ambient x{final['ambient_ratio']:.3f}; converged at frame {f['converged_at_frame']}{sphere}")
    print(f"wrote {args.output / 'estimates.jsonl'}, scores.json, scores.png")
    return 0


# arsim render


def _check_growing(r, light_given: bool) -> None:
    if light_given and r.prt_light == "growing":
        raise ArsimError('[render] prt_light = "growing" replays the probe as the capture grew; give no --env or --maps '
                         '(a light given whole did not grow), or set prt_light = "final"')


def cmd_render(args: argparse.Namespace) -> int:
    from arsim.lighting.bake_output import read_bake
    from arsim.render.content import scene_objects
    from arsim.render.session import SessionSettings, check_maps, maps_needed
    from arsim.capture.pipeline import recording_scenario
    from arsim.run.stages import recorded_pair, render_session

    recording = None
    if args.scenario is not None and detect_format(args.scenario) is not None:  # a recording made before, any layout
        if args.recording is not None:
            raise ArsimError(f"{args.scenario} is a recording and --recording gives another; give one of them")
        recording = recorded_pair(args.scenario)
        scenario = recording_scenario(recording[0])
    else:
        scenario = load_scenario(args.scenario)
        if args.recording is not None:  # replayed with this scenario's objects
            recording = recorded_pair(args.recording)
    if recording is None:  # (recorded now: the scenario must make an AR path)
        if not scenario.ar.enabled:
            raise ArsimError(f"{args.scenario or 'the scenario'}: [ar] enabled = false; the session needs the AR path: set it to true")
        recording_segments(scenario)
    r = scenario.render
    method, map_size = args.method or r.method, args.map_size or r.map_size
    if args.env is not None and args.maps:
        raise ArsimError("--env and --maps both give the light: pass one of them")
    _check_growing(r, args.env is not None or bool(args.maps))
    objects = scene_objects(r, scenario.ar.table_albedo)  # a mesh that cannot be read fails here, before any work
    maps = None
    if args.maps:  # maps baked before (`arsim bake`), one folder per method
        maps = {}
        for folder in args.maps:
            baked = read_bake(folder)
            maps[baked.method] = maps[baked.method].merged(baked) if baked.method in maps else baked
        check_maps(maps, maps_needed(objects, method))
        sizes = {m.size for m in maps.values()}
        if len(sizes) > 1:
            raise ArsimError(f"the --maps folders hold maps of sizes {sorted(sizes)}; give maps of one size")
        map_size = sizes.pop()
    probe = _probe(args.env, map_size) if args.env is not None else None  # read early: a bad file fails first
    log_average = r.log_average if args.log_average is None else args.log_average
    overlay = r.overlay if args.overlay is None else args.overlay
    settings = SessionSettings(method, args.key or r.key, args.white or r.white, log_average, every=args.every, overlay=overlay,
                               flip_every=r.flip_every)
    source = str(args.env) if args.env is not None else ", ".join(map(str, args.maps)) if args.maps else "captured"
    with _output(args, _scenario_file(args.scenario), args.env, args.recording, *(args.maps or ())) as work:
        metrics = render_session(scenario, work, settings, map_size, probe, maps, source, _bar, objects, recording)
    out = args.output
    flip = (f"FLIP against the truth frame {metrics['flip_mean']:.4f}" if "flip_mean" in metrics
            else "not scored (the true environment is unknown)")
    if metrics.get("lit_by_truth"):
        flip += " (0 by construction, not a result: the objects were lit by the true environment's own maps)"
    print(f"rendered {metrics['frames_total']} frames ({metrics['frames_lost']} lost) into {out}: {_tracking_p95(metrics)}; "
          f"{flip}; metrics in {out / 'metrics.json'}")
    for why in metrics.get("truth", {}).values():
        print(f"note: the truth is {why}")
    return 0


def _check_recording(folder: Path) -> None:
    """--recording: a recording (any layout) with its AR path, both loaded and checked before any output."""
    from arsim.run.stages import recorded_pair

    if not folder.exists():
        raise ArsimError(f"{folder}: no such recording; make one with `arsim record SCENARIO -o REC`")
    recorded_pair(folder)


def _tile_policy(text: str) -> int | None:
    """--tile and [profile] tile: a tile side, or auto (None)."""
    if text.strip().lower() == "auto":
        return None
    try:
        value = int(text)
    except ValueError:
        raise ArsimError(f"tile policy {text!r} is neither a tile side nor auto; give e.g. 64 or auto") from None
    if value < 1:
        raise ArsimError(f"tile side {value} is not positive; give e.g. 64 or auto")
    return value


def cmd_profile(args: argparse.Namespace) -> int:
    from arsim.evaluate.profile import sweep_table
    from arsim.render.baking import BakeSettings
    from arsim.render.content import scene_objects
    from arsim.run.stages import profile_session

    scenario = load_scenario(args.scenario)
    if not scenario.ar.enabled:
        raise ArsimError(f"{args.scenario or 'the scenario'}: [ar] enabled = false; the profile needs the AR path: set it to true")
    recording_segments(scenario)
    r, pr = scenario.render, scenario.profile
    map_size = args.map_size or r.map_size
    budget = args.budget_ms if args.budget_ms is not None else pr.budget_ms
    if args.sweep is not None:
        entries = [e for e in args.sweep.split(",") if e.strip()]
        if not entries:
            raise ArsimError("--sweep has no entries; give tile policies, e.g. --sweep 32,64,128,auto")
        policies = [_tile_policy(e) for e in entries]
    else:
        policies = [_tile_policy(args.tile if args.tile is not None else pr.tile)]
    method = args.bake or pr.bake
    bakes = [BakeSettings(method, tile) for tile in policies]
    for b in bakes:
        b.check(map_size)  # a tile that does not divide the maps fails here, before any work
    _check_growing(r, args.env is not None)
    objects = scene_objects(r, scenario.ar.table_albedo)
    probe = _probe(args.env, map_size) if args.env is not None else None  # read early: a bad file fails first
    with _output(args, _scenario_file(args.scenario), args.env) as work:
        runs = profile_session(scenario, work, bakes, budget, args.max_frames or pr.max_frames, map_size, probe, _bar, objects)
    out = args.output
    for run in runs:
        s = run.summary()
        bake = s["bake"]
        state = (f"bake complete after {bake['frames_to_finish']} frames ({bake['seconds']:.1f} s), worst frame "
                 f"{bake['worst_frame_ms']:.1f} ms" if bake["completed"] else "bake not complete")
        print(f"tile {run.label}: {s['frames']} frames, {s['within_budget_pct']:.2f} % within {budget:.1f} ms; {state}")
    if len(runs) > 1:
        print(sweep_table(runs))
    print(f"profile in {out / 'profile.md'}, trace(s) for Perfetto or chrome://tracing, timeline plot(s)")
    return 0


# --------------------------------------------------------------------------------------------------
# arsim convert


def cmd_convert(args: argparse.Namespace) -> int:
    if args.output.suffix.lower() not in (".exr", ".hdr", ".png"):
        raise ArsimError(f"{args.output}: unknown output type '{args.output.suffix}'; use .exr, .hdr or .png")
    image, replaced = replace_nonfinite(read_hdr(args.input), args.nan, str(args.input))
    layout = args.layout or detect_layout(image, str(args.input))
    out = to_layout(image, layout, args.size)
    write_image(args.output, out)
    if replaced:
        print(f"replaced {replaced} NaN/Inf texels with 0")
    kind = "angle map" if layout == "anglemap" else "equirect"
    print(f"wrote {args.output} ({out.shape[1]} x {out.shape[0]} {kind})")
    return 0


# --------------------------------------------------------------------------------------------------
# arsim export


def cmd_export(args: argparse.Namespace) -> int:
    """A recording into another layout, or maps / a probe into the formats engines load: the formats say which."""
    recording = [f for f in args.format if f in RECORDING_FORMATS]
    if recording and len(recording) != len(args.format):
        raise ArsimError(f"--format {','.join(args.format)} mixes a recording's layout ({', '.join(RECORDING_FORMATS)}) with "
                         "maps' formats; export a recording or maps, one at a time")
    if recording:
        given = [name for name, value in (("--env", args.env), ("--size", args.size)) if value is not None]
        if given:
            raise ArsimError(f"{' and '.join(given)}: for maps and probes only, not a recording; leave "
                             f"{'it' if len(given) == 1 else 'them'} out")
        if len(recording) > 1:
            raise ArsimError(f"--format {','.join(args.format)}: a recording is written in one layout at a time; give one")
        return _export_recording(args)
    if args.input.is_dir() and detect_format(args.input) is not None:
        raise ArsimError(f"{args.input} is a recording, which is written in a layout: --format one of "
                         f"{', '.join(RECORDING_FORMATS)} (maps for engines come from a bake or a probe)")
    return _export_maps(args)


def _export_maps(args: argparse.Namespace) -> int:
    """MAPS (a bake folder) or PROBE (an HDR image) in the formats engines load (lighting/export.py)."""
    from arsim.lighting.export import check_face_size, check_formats, check_source, export_maps, load_source

    formats = check_formats(args.format)  # before any work or output
    check_face_size(args.size)
    source = load_source(args.input, args.env)
    check_source(source, formats)
    with _output(args, args.input, args.env) as work:
        with progress_bar("exporting", len(formats)) as update:
            step = iter(range(len(formats)))
            result = export_maps(source, formats, work, args.size, f".{args.image}", args.texel,
                                 progress=lambda name: update(completed=next(step), description=f"exporting {name}"))
    for name, seconds in result.seconds.items():
        print(f"{name:<9} {seconds:6.2f} s")
    print(f"wrote {len(result.files)} files to {args.output}")
    return 0


# --------------------------------------------------------------------------------------------------
# arsim bake, arsim compare-methods


def _map_size(text: str) -> int:
    value = _size(text)
    if not is_map_size(value):
        raise argparse.ArgumentTypeError(f"size {value} is not allowed: maps need a power of two from 8 up (64, 128, 256, 512, ...)")
    return value


def _exponents(text: str) -> list[float]:
    values = []
    for part in text.split(","):
        try:
            value = float(part)
        except ValueError:
            raise argparse.ArgumentTypeError(f"Phong exponent {part.strip()!r} is not a number; give e.g. --spec 1,10,80") from None
        if not (np.isfinite(value) and 0 < value <= MAX_EXPONENT):
            raise argparse.ArgumentTypeError(f"Phong exponent {part.strip()} is not allowed: exponents must be positive "
                                             f"numbers up to {MAX_EXPONENT:g}")
        if value in values:
            raise argparse.ArgumentTypeError(f"Phong exponent {part.strip()} is given twice; give each once")
        values.append(value)
    return values


def _positive(name: str, kind: type = int):
    """An argparse type: a positive number of `kind` (int: at least 1; float: finite and above 0)."""
    noun, allowed = ("an integer", "give at least 1") if kind is int else ("a number", "give a positive number")

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r} is not {noun}") from None
        if not (np.isfinite(value) and value > 0):
            raise argparse.ArgumentTypeError(f"{name} {value:g} is out of range: {allowed}")
        return value

    return parse


def _max_flip(text: str) -> float:
    """--max-flip: a finite tolerance from 0 (a gate with NaN or inf would pass everything)."""
    try:
        return check_max_flip(float(text), "--max-flip")
    except ValueError:
        raise argparse.ArgumentTypeError(f"--max-flip {text!r} is not a number; give e.g. {DEFAULT_MAX_FLIP:g}") from None
    except ArsimError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _non_negative(name: str):
    """An argparse type: an integer from 0 (a seed)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{name} {text!r} is not an integer") from None
        if value < 0:
            raise argparse.ArgumentTypeError(f"{name} {value} is negative: give 0 or more")
        return value

    return parse


def _orders(text: str) -> list[int]:
    """--sh-orders: integers, each in the sh method's range (checked by compare's check_request)."""
    try:
        return [int(o) for o in text.split(",") if o.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sh-orders {text!r} is not a list of integers; give e.g. 5,10,20") from None


def _probe(path: Path, size: int | None) -> np.ndarray:
    """The environment as an angle map of the given size; an angle map of that size is used as it is."""
    return _probe_and_source(path, size)[0]


def _probe_and_source(path: Path, size: int | None) -> tuple[np.ndarray, np.ndarray]:
    """_probe's angle map, and the image as read (which `sht` and `sh` may sum at their own resolution)."""
    image, _ = replace_nonfinite(read_hdr(path), "refuse", str(path))
    layout = detect_layout(image, str(path))
    if layout == "anglemap" and size in (None, image.shape[0]):
        if not is_map_size(image.shape[0]):
            raise ArsimError(f"{path}: angle map size {image.shape[0]} is not a power of two from 8 up; pass --size 256 (or 512, ...)")
        return image, image
    return to_layout(image, "anglemap", size or 512), image


def _parameters(args: argparse.Namespace) -> MapParameters:
    return MapParameters(sh_order=args.sh_order, sh_faithful=args.sh_faithful, sh_window=args.sh_window,
                         samples=args.samples, seed=args.seed, mc_texels=args.mc_texels)


def _tracking_p95(m: dict) -> str:
    """The tracking's 95th percentiles in words; infinite where more than 5 % of the frames with the tag
    in view were lost (a lost frame counts as an infinite error)."""
    if "tracking_rot_err_deg_p95" not in m:
        return "tracking not measured (no ground truth)"
    rot, pct = m["tracking_rot_err_deg_p95"], m["tracking_trans_err_pct_p95"]
    if m["frames_tag_visible"] == 0:
        return "tracking p95 n/a (the tag was never wholly in view)"
    if not (math.isfinite(rot) and math.isfinite(pct)):
        lost = m["frames_tag_visible"] - round(m["detection_rate_visible"] * m["frames_tag_visible"])
        return f"tracking p95 unbounded ({lost} of the {m['frames_tag_visible']} frames with the tag in view lost, more than 5 %)"
    return f"tracking p95 {rot:.2f} degrees, {pct:.2f} % of the distance"


def _scenario_file(path: Path | None) -> Path | None:
    """The file a scenario argument names (a bundled name resolved), for the check that -o holds no input."""
    return scenario_path(path) if path is not None else None


def _final(paths: list[Path], work: Path, output: Path) -> list[Path]:
    """Where files written into the temporary folder `work` lie once it has become -o."""
    return [output / p.relative_to(work) for p in paths]


@contextlib.contextmanager
def _output(args: argparse.Namespace, *inputs: Path | None):
    """-o's folder, checked before any work (core/files.check_output_folder); yields the temporary folder
    the command writes into, which becomes -o whole when the command succeeds."""
    check_output_folder(args.output, args.force, inputs)
    with staged_folder(args.output, args.command) as work:
        yield work


def cmd_bake(args: argparse.Namespace) -> int:
    params = _parameters(args)
    params.check()  # before any work or output
    env, source = _probe_and_source(args.env, args.size)
    with _output(args, args.env) as work:
        with progress_bar(f"baking {len(args.spec)} maps ({args.method})", len(args.spec)) as update:
            result = bake(env, args.spec, args.method, params, progress=lambda k: update(completed=k), source=source)
        write_bake(work, args.spec, args.method, params, result, str(args.env))
    out = args.output
    print(f"wrote {len(args.spec)} maps ({args.method}, {env.shape[0]}² angle maps, summed over the {result.summed_over}) "
          f"to {out} in {result.seconds_total:.2f} s")
    return 0


def cmd_compare_methods(args: argparse.Namespace) -> int:
    check_request(args.methods, _parameters(args), args.sh_orders)  # before any work or output
    env = _probe(args.env, args.size)
    stages = 0

    def on_stage(stage: str) -> None:
        nonlocal stages
        update(completed=stages, description=stage)
        stages += 1

    with _output(args, args.env) as work:
        with progress_bar("comparing methods", len(args.methods) + 3) as update:
            comparison = compare(env, args.spec, args.methods, _parameters(args), args.reference_texels,
                                 args.sh_orders, progress=on_stage)
        paths = _final(write_comparison(comparison, work), work, args.output)
    width = max((len(comparison.label(name)) for name in comparison.errors), default=0)
    for name, errors in comparison.errors.items():
        worst_mean = max(e["mean"] for e in errors)
        worst_max = max(e["max"] for e in errors)
        print(f"{comparison.label(name):<{width}}  mean error up to {worst_mean:8.3f} %  max error up to {worst_max:9.2f} %  "
              f"{comparison.seconds[name]:7.2f} s")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


# --------------------------------------------------------------------------------------------------
# arsim bases


def cmd_bases_compare(args: argparse.Namespace) -> int:
    from arsim.evaluate.compare_bases import bases_study, parse_entries, visual_environment

    selected = parse_entries(args.bases) if args.bases else None  # bad names fail here, before any work
    if not 0.0 <= args.sun_elevation <= 90.0:
        raise ArsimError(f"--sun-elevation {args.sun_elevation:g} is not an elevation: give 0 to 90 degrees")
    environment = visual_environment(args.env)  # a file that cannot be read fails here, before any output
    with _output(args, args.env) as work, progress_bar("comparing bases", args.signals) as update:
        study = bases_study(work, args.signals, args.seed, selected, environment, args.sun_elevation, args.sun_share,
                            progress=lambda k: update(completed=k))
        paths = _final(study.paths, work, args.output)
    for key, stats in study.errors.items():
        print(f"{key:<14} mean error {100 * stats['mean']:8.3f} %   visual {100 * study.visual_errors[key]:7.3f} %")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


# --------------------------------------------------------------------------------------------------
# arsim prt


def cmd_prt_compare(args: argparse.Namespace) -> int:
    from arsim.core.assets import assets_dir
    from arsim.evaluate.prt_compare import DEFAULT_PROBES, prt_study
    from arsim.lighting.prt import check_order, get_variant

    for v in args.variants:  # bad names and orders fail here, before any work
        get_variant(v)
    check_order(args.order)
    if args.samples > 65536:
        raise ArsimError(f"--samples {args.samples}: give at most 65536 directions per texel (memory grows with them)")
    paths = args.env or [assets_dir() / "envmaps" / f"{name}.exr" for name in DEFAULT_PROBES]
    probes = {Path(p).stem: _probe(p, 128) for p in paths}
    with _output(args, *args.env) as work, progress_bar("comparing PRT variants", 1.0) as update:
        written, scores = prt_study(work, probes, args.variants, args.order, args.samples,
                                    progress=lambda f, label: update(completed=f, description=f"PRT: {label}"))
        written = _final(written, work, args.output)
    for probe, row in scores.items():
        print(f"{probe:<10} " + "  ".join(f"{name} FLIP {v['flip']:.3f}" for name, v in row.items()))
    print("wrote " + ", ".join(str(p) for p in written))
    return 0


# --------------------------------------------------------------------------------------------------
# arsim validate


def cmd_run(args: argparse.Namespace) -> int:
    from arsim.evaluate.diff import baseline_figures, frames_of, run_diff, update_baseline
    from arsim.run.pipeline import disk_summary, run_scenario

    scenario = load_scenario(args.scenario)
    if args.update_baseline and args.baseline is None:
        raise ArsimError("--update-baseline needs --baseline DIR: the folder to write the baseline into")
    if args.baseline is not None and not args.update_baseline:
        frames_of(args.baseline)  # a baseline without frames fails here, before any work
    if args.recording is not None:
        _check_recording(args.recording)
    source = str(args.scenario) if args.scenario is not None else "the embedded default scenario"

    from arsim.run.cache import StageCache, cache_folder

    cache = StageCache(cache_folder(args.cache, args.no_cache))
    result = None
    baseline_metrics = baseline_figures(args.baseline) if args.baseline is not None and not args.update_baseline else None
    with _output(args, _scenario_file(args.scenario), args.recording, args.baseline) as work:
        manifest = run_scenario(scenario, source, work, args.recording, _bar, cache, baseline_metrics, args.keep_recording)
        if args.baseline is not None and not args.update_baseline:
            result = run_diff(args.baseline, work, work / "diff", args.max_flip)
    out = args.output
    s = manifest["metrics"]["session"]
    print(f"run {scenario.run.name} in {out}: {s['frames_total']} frames ({s['frames_lost']} with the tag lost), "
          f"{_tracking_p95(s)}, " + (f"FLIP against the truth frame {s['flip_mean']:.4f}" if "flip_mean" in s else
                                      "frames not scored (the true environment is unknown)")
          + f"; report {out / 'report' / 'index.html'}")
    for name, st in manifest["stages"].items():
        where = f"from {st['from']}" if st["from"] else (f"stored in {st['stored']}" if st.get("stored") else "not cached")
        cpu = st.get("cpu_seconds", 0.0)
        print(f"  {name:<10} {st['status']:<8} {st['seconds']:7.2f} s  CPU {cpu:7.2f} s ({cpu / max(st['seconds'], 0.01):4.0%})"
              f"  key {st['key']}  {where}")
    for why in manifest["metrics"].get("truth", {}).values():
        print(f"note: the truth is {why}")
    print(f"run: {disk_summary(manifest, out)}")
    if args.update_baseline:
        print(f"baseline written: {update_baseline(out, args.baseline)}")
    elif result is not None:
        print(f"against the baseline {args.baseline}: {'passed' if result.passed else 'FAILED'}: {result.message()}; "
              f"page {out / 'diff' / 'index.html'}")
        return 0 if result.passed else 1
    return 0


def cmd_batch(args: argparse.Namespace) -> int:
    from arsim.run.batch import check_ray_address, run_batch

    for path in args.scenarios:
        load_scenario(path)  # a scenario that does not parse fails here, before any run
    if args.ray is not None:
        check_ray_address(args.ray)
    finished = []

    def done(result):
        finished.append(result)
        state = "done" if result["ok"] else "failed"
        update(completed=len(finished), description=f"{title}: {Path(result['scenario']).stem} {state}")

    title = f"running {len(args.scenarios)} scenarios"
    with (_output(args, *map(_scenario_file, args.scenarios), args.baselines) as work,
          progress_bar(title, len(args.scenarios), every_update=True) as update):
        summary = run_batch(args.scenarios, work, args.workers, args.ray, args.baselines, args.max_flip, done,
                            cache=args.cache, no_cache=args.no_cache)
    out = args.output
    for s in summary["scenarios"]:
        if not s["ok"]:
            print(f"arsim batch: {s['name']} failed: {s['error']}", file=sys.stderr)
    print(f"{len(summary['scenarios'])} scenarios in {summary['timing']['wall_s']:.1f} s ({summary['timing']['backend']}); "
          f"failed: {', '.join(summary['failed']) or 'none'}; regressions: {', '.join(summary['regressions']) or 'none'}; "
          f"summary {out / 'summary.md'}")
    return 1 if summary["failed"] or summary["regressions"] else 0


def cmd_cache(args: argparse.Namespace) -> int:
    from arsim.run.cache import StageCache, default_cache_dir

    cache = StageCache(args.cache if args.cache is not None else default_cache_dir())
    if args.action == "clear":
        print(f"removed {cache.clear()} entries from {cache.root}")
        return 0
    info = cache.info()
    if args.json:
        print(json_text(info), end="")
        return 0
    print(f"run cache {info['folder']}: {info['entries']} entries, {info['bytes'] / 2**20:.1f} MiB "
          f"(at most {info['max_bytes'] / 2**30:.1f} GiB kept)")
    for stage, s in info["stages"].items():
        print(f"  {stage:<10} {s['entries']:4d} entries {s['bytes'] / 2**20:10.1f} MiB")
    return 0


def cmd_diff(args: argparse.Namespace) -> int:
    from arsim.evaluate.diff import run_diff

    with (_output(args, args.a, args.b) if args.output is not None else contextlib.nullcontext()) as work, \
            progress_bar("comparing frames", 1.0) as update:
        result = run_diff(args.a, args.b, work, args.max_flip, progress=lambda f: update(completed=f),
                          gate_times=args.gate_times)
    out = args.output
    summary = result.summary()
    where = f"; page {out / 'index.html'}" if out is not None else ""
    if result.metrics:
        print(result.metrics_table())
    print(f"{'passed' if result.passed else 'FAILED'}: {result.message()}\n"
          f"FLIP mean over frames {summary['flip_mean']:.5f}, worst {summary['flip_max']:.5f} ({summary['worst_frame']}){where}")
    return 0 if result.passed else 1


def cmd_validate(args: argparse.Namespace) -> int:
    from arsim.render.content import scene_objects
    from arsim.scenario.environment import read_environment

    scenario = load_scenario(args.scenario)
    recording_segments(scenario)
    read_environment(scenario.environment)  # a PNG renamed .exr, a truncated file, NaN texels: refused as record would
    scene_objects(scenario.render, scenario.ar.table_albedo)  # a mesh that cannot be read: refused as render would
    print(f"# {args.scenario or DEFAULT_SCENARIO}: valid; as resolved:")
    print(scenario_to_toml(scenario), end="")
    return 0


# --------------------------------------------------------------------------------------------------


SCENARIO_HELP = ("a scenario .toml, or a bundled scenario's name (" + ", ".join(bundled_scenarios())
                 + "); default: the embedded default scenario")


def _info_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "info", "print size, layout, radiance range and bad-texel counts of an HDR image, "
                 "or check a recording or a run directory (every file its manifest lists) and summarise it",
                 "arsim info assets/envmaps/sunrise.exr   (or: arsim info rec, arsim info run)")
    p.add_argument("file", type=_path, metavar="FILE",
                   help="OpenEXR (.exr) or Radiance (.hdr) image, a recording (arsim's, EuRoC's or TUM-VI's folder, or a "
                   "ROS 2 bag) or a run directory")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")
    p.set_defaults(run=cmd_info)


def _convert_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "convert", "convert an HDR image between layouts, sizes and formats (.exr, .hdr, .png preview)",
                 "arsim convert assets/envmaps/city.exr city_anglemap.exr --layout anglemap --size 512")
    p.add_argument("input", type=_path, metavar="IN", help="OpenEXR (.exr) or Radiance (.hdr) image, equirect 2:1 or angle map 1:1")
    p.add_argument("output", type=_path, metavar="OUT", help=".exr (float32 RGB), .hdr, or .png (tone-mapped 8-bit preview)")
    p.add_argument("--layout", choices=LAYOUTS, help="layout of OUT (default: that of IN)")
    p.add_argument("--size", type=_size, metavar="N",
                   help="N of an N x N angle map, or the height N of a 2N x N equirect (default: the height of IN)")
    p.add_argument("--nan", choices=NONFINITE_POLICIES, default="refuse",
                   help="what to do with NaN/Inf texels: refuse the image (default) or replace them with 0")
    p.set_defaults(run=cmd_convert)


def _output_option(p: argparse.ArgumentParser, what: str, required: bool = True) -> None:
    """-o and --force, the same for every command that writes a folder (the policy: core/files.check_output_folder)."""
    p.add_argument("-o", "--output", type=_path, required=required, metavar="DIR",
                   help=f"{what}; written whole when the command succeeds, replacing an earlier arsim output there")
    p.add_argument("--force", action="store_true",
                   help="replace DIR even if it holds files arsim did not write (they are deleted)")


def _map_options(p: argparse.ArgumentParser) -> None:
    """What bake and compare-methods share: the environment, the output folder, the maps and their parameters."""
    p.add_argument("env", type=_path, metavar="ENV", help="HDR environment, equirect 2:1 or angle map 1:1 (.exr or .hdr)")
    _output_option(p, "output folder")
    p.add_argument("--size", type=_map_size, metavar="N",
                   help="N of the N x N angle maps, a power of two from 8 (default: an angle map's own size, else 512)")
    p.add_argument("--spec", type=_exponents, default=list(DEFAULT_EXPONENTS), metavar="S,S,...",
                   help="Phong exponents; 1 is the irradiance map (default: " + ",".join(map(str, DEFAULT_EXPONENTS)) + ")")
    p.add_argument("--sh-order", type=_positive("--sh-order"), default=MapParameters.sh_order, metavar="L",
                   help=f"sh: bands 0..L-1, L² coefficients (default {MapParameters.sh_order})")
    p.add_argument("--sh-faithful", action="store_true",
                   help="sh: evaluate Y_lm with factorials in double precision as the thesis's Alg. 2.5/2.6")
    p.add_argument("--sh-window", choices=WINDOWS, default=MapParameters.sh_window,
                   help="sh: plain truncation (none, the default) or a window against ringing (README: Irradiance and reflection maps)")
    p.add_argument("--samples", type=_positive("--samples"), default=MapParameters.samples, metavar="K",
                   help=f"mc: importance samples per point: a texel, or a point of the lobe's grid (default {MapParameters.samples})")
    p.add_argument("--seed", type=_non_negative("--seed"), default=0, help="mc: random seed, 0 or more (default 0)")
    p.add_argument("--mc-texels", action="store_true",
                   help="mc: estimate every lobe at every texel (a per-texel grain, 4-6x slower at 512²) instead of on "
                        "a grid as fine as the lobe needs, read bicubically (README: mc and the speed of sh over its orders)")


def _bake_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "bake", "compute irradiance and reflection maps of an HDR environment with one method",
                 "arsim bake assets/envmaps/courtyard.exr -o maps --method fast --size 512 --spec 1,10,80")
    _map_options(p)
    p.add_argument("--method", choices=list(METHODS), default="fast",
                   help="; ".join(f"{m.name}: {m.summary}" for m in METHODS.values()) + " (default fast). "
                        + " and ".join(n for n, m in METHODS.items() if m.from_source) + " sum an equirect ENV with more "
                        "texels than the N x N maps at its own resolution (bake.json: summed_over)")
    p.set_defaults(run=cmd_bake)


def _export_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "export", "write a recording in a layout other tools read (EuRoC / ASL folders, TUM-VI's with "
                 "exposure times and the photometric calibration, a ROS 2 bag), or maps for engines: a bake folder (MAPS) or "
                 "a light probe (PROBE) as KTX2 cube maps (GGX chain, radiance, Phong maps, BRDF table), Filament's sh.txt, "
                 "a glTF scene with EXT_lights_image_based, cube faces or equirects",
                 "arsim export maps -o engine --format ktx2,filament,gltf   (or: arsim export rec --format euroc -o rec_euroc; "
                 "arsim export assets/envmaps/city.exr -o city --format gltf)")
    p.add_argument("input", type=_path, metavar="RECORDING|MAPS|PROBE",
                   help="a recording (arsim's, EuRoC's, TUM-VI's folder or a ROS 2 bag), a folder written by `arsim bake`, "
                        "or an HDR image (.exr or .hdr), angle map 1:1 or equirect 2:1")
    _output_option(p, "output folder (a recording's AR path goes to DIR/ar)")
    p.add_argument("--format", type=lambda t: [f.strip() for f in t.split(",") if f.strip()], required=True, metavar="F,F,...",
                   help=f"a recording: one of {', '.join(RECORDING_FORMATS)} (README: Recordings in standard layouts); maps "
                        "or a probe: one or more of ktx2, filament, gltf, faces, equirect (README: Maps for engines)")
    p.add_argument("--env", type=_path, metavar="PROBE",
                   help="MAPS: the probe they were baked from (default: the one bake.json names, if found)")
    p.add_argument("--size", type=_size, metavar="N",
                   help="cube faces N x N, a power of two from 16 to 2048 (default: a quarter of the probe's side); "
                        "equirects 2N high")
    p.add_argument("--image", choices=("exr", "hdr", "png"), default="exr",
                   help="faces' and equirects' files: exr (float32), hdr (RGBE) or png (tone-mapped preview); default exr")
    p.add_argument("--texel", choices=("rgba16f", "b10g11r11"), default="rgba16f",
                   help="the KTX2 cube maps' texels: half floats RGBA (default) or packed unsigned floats (half the size)")
    p.set_defaults(run=cmd_export)


def _bases_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "bases", "irradiance normal mapping's bases (SH, Half-Life 2, H-basis, modified H-basis, HSH, Makhotkin, "
                 "Zernike): `compare` measures how well each holds directional irradiance",
                 "arsim bases compare -o bases --signals 200")
    bases_sub = p.add_subparsers(dest="bases_command", metavar="ACTION", parser_class=_Parser, required=True)
    q = _command(bases_sub, "compare", "the integrated squared error of each basis and coefficient count over random "
                 "irradiance signals (bases.md, bases.json, bases.png) and a normal-mapped plane under one environment "
                 "with a grazing sun, a tile per basis (visual.png, visual_errors.png)",
                 "arsim bases compare -o bases --signals 200   (or: --bases h6,modh6,sh9,hsh9 --env assets/envmaps/sunrise.exr)")
    _output_option(q, "output folder")
    q.add_argument("--signals", type=_positive("--signals"), default=100, metavar="N",
                   help="random irradiance signals to average over (default 100)")
    q.add_argument("--seed", type=_non_negative("--seed"), default=0, help="the first signal's seed, 0 or more (default 0)")
    q.add_argument("--bases", type=lambda t: [b.strip() for b in t.split(",") if b.strip()], metavar="B,B,...",
                   help="bases with their counts, e.g. sh9,hl2,h4,h6,modh6,hsh9,makhotkin9,zernike6,sh-rh9 (default: all)")
    q.add_argument("--env", type=_path, metavar="ENV.exr", help="the visual comparison's environment (default: assets' interior.exr)")
    q.add_argument("--sun-elevation", type=float, default=8.0, metavar="DEG",
                   help="the visual comparison's sun elevation in degrees (default 8: grazing)")
    q.add_argument("--sun-share", type=_positive("--sun-share", float), default=3.0, metavar="X",
                   help="the sun's irradiance at normal incidence, in units of the sky's on the plane (default 3)")
    q.set_defaults(run=cmd_bases_compare)


def _prt_parser(sub: argparse._SubParsersAction) -> None:
    from arsim.lighting.prt import DEFAULT_ORDER, MAX_ORDER, MIN_ORDER, VARIANTS

    p = _command(sub, "prt", "precomputed radiance transfer with normal maps (the normal-mapping-prt spec): `compare` "
                 "measures its variants against a per-pixel reference", "arsim prt compare -o prt")
    prt_sub = p.add_subparsers(dest="prt_command", metavar="ACTION", parser_class=_Parser, required=True)
    q = _command(prt_sub, "compare", "the variants (gs, sep, sep-c, hl2, sal) and the plain PRT on a normal-mapped torus "
                 "against a per-pixel reference under three probes: FLIP and relative MSE (prt_compare.md/.json), the "
                 "images side by side (variants.png), and the SH of bands 0-2 fitted in each hemispherical basis "
                 "(sh_projection.json/.md)",
                 "arsim prt compare -o prt   (or: --env assets/envmaps/studio.exr --order 7 --variants gs,sep-c)")
    _output_option(q, "output folder")
    q.add_argument("--env", type=_path, nargs="+", default=[], metavar="ENV",
                   help="the probes (HDR environments; default: the bundled interior, sunrise and city)")
    q.add_argument("--order", type=int, default=DEFAULT_ORDER, metavar="L",
                   help=f"bands of the light's SH, {MIN_ORDER} to {MAX_ORDER} (default {DEFAULT_ORDER}: bands 0-4)")
    q.add_argument("--samples", type=_positive("--samples"), default=1024, metavar="K",
                   help="directions per light-map texel of the transfer (default 1024)")
    q.add_argument("--variants", type=lambda t: [v.strip() for v in t.split(",") if v.strip()], default=list(VARIANTS),
                   metavar="V,V,...", help=f"the variants (default all: {','.join(VARIANTS)})")
    q.set_defaults(run=cmd_prt_compare)


def _compare_methods_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "compare-methods", "measure every map method against accurate: tables, a figure grid, SH error by order",
                 "arsim compare-methods assets/envmaps/courtyard.exr -o compare --size 128")
    _map_options(p)
    p.add_argument("--methods", type=lambda t: [m.strip() for m in t.split(",")], default=[m for m in METHODS if m != "accurate"],
                   metavar="M,M,...", help="methods to compare (default: all but accurate, which is the reference)")
    p.add_argument("--reference-texels", type=_positive("--reference-texels"), metavar="K",
                   help="texels the accurate reference is computed at (default: all up to 128², else 2000 random)")
    p.add_argument("--sh-orders", type=_orders,
                   default=list(DEFAULT_SH_ORDERS), metavar="O,O,...",
                   help="orders of the SH error-against-order study (default " + ",".join(map(str, DEFAULT_SH_ORDERS)) + "; empty to skip)")
    p.set_defaults(run=cmd_compare_methods)


def _record_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "record", "synthesise the capture sweep of a scenario (frames, IMU streams, fused orientation, truth) and, "
                 "unless [ar] enabled = false, the AR path around the table and tag into DIR/ar",
                 "arsim record scenarios/indoor.toml -o rec")
    p.add_argument("scenario", type=_path, nargs="?", metavar="SCENARIO", help=SCENARIO_HELP)
    _output_option(p, "recording folder")
    p.add_argument("--compact", action="store_true",
                   help="each segment's frames in one lossless FFV1 video (frames.mkv) instead of a PNG per frame: "
                        "the same pixels, about 0.88 of the size")
    p.set_defaults(run=cmd_record)


def _capture_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "capture", "stitch a recording's frames into an HDR angle-map light probe, correcting the IMU's drift "
                 "by feature alignment, and measure it against the truth (records the scenario's sweep first if given one)",
                 "arsim capture rec -o capture   (or: arsim capture scenarios/indoor.toml -o capture)")
    p.add_argument("source", type=_path, nargs="?", metavar="SCENARIO|RECORDING",
                   help="a recording (arsim's, EuRoC's or TUM-VI's folder, or a ROS 2 bag), or a scenario (.toml or a "
                   "bundled name) to record first; default: the embedded default scenario")
    _output_option(p, "output folder")
    p.add_argument("--size", type=_map_size, metavar="N", help="N of the captured N x N angle map (default: [capture] capture_size, 512)")
    p.add_argument("--align-every", type=_positive("--align-every"), metavar="K",
                   help="align every K-th metered frame against the probe (default: [capture] align_every, 1)")
    p.set_defaults(run=cmd_capture)


def _estimate_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "estimate", "light estimates in the shapes phones report (SH of the radiance, main light, cubemap, "
                 "ambient intensity, colour correction) per frame of a sweep, from the truth, from the probe as the capture "
                 "builds it, and from a file of yours, scored against the truth: estimates.jsonl, scores.json, scores.png",
                 "arsim estimate rec -o estimates   (or: arsim estimate quick -o estimates --file mine.jsonl)")
    p.add_argument("source", type=_path, nargs="?", metavar="SCENARIO|RECORDING",
                   help="a recording folder, or a scenario (.toml or a bundled name) whose sweep is recorded first; default: "
                        "the embedded default scenario")
    _output_option(p, "output folder")
    p.add_argument("--file", type=_path, metavar="ESTIMATES.jsonl",
                   help="your estimates to score too: per line frame, sh_radiance (27), main_light (direction_world, "
                        "intensity_rgb), ambient_intensity, color_correction (4)")
    p.set_defaults(run=cmd_estimate)


def _session_options(p: argparse.ArgumentParser, env_help: str, recording: bool = False) -> None:
    """What render and profile share: the scenario (or, for render, a recording), the output folder, the light's
    file, the maps' size."""
    p.add_argument("scenario", type=_path, nargs="?", metavar="SCENARIO|RECORDING" if recording else "SCENARIO",
                   help=SCENARIO_HELP + ("; or a recording with its AR path (arsim's, EuRoC's or TUM-VI's folder, "
                                         "or a ROS 2 bag), rendered as it is" if recording else ""))
    _output_option(p, "output folder")
    p.add_argument("--env", type=_path, metavar="PROBE.exr", help=env_help)
    p.add_argument("--map-size", type=_map_size, metavar="N", help="N of the N x N maps (default: [render] map_size, 128)")


def _render_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "render", "run the AR session: record the scenario, capture the probe (or take --env), track the tag, "
                 "render the virtual objects lit by the maps, tone-map them over the camera frames, and compare each "
                 "frame with the truth frame (the objects lit by the true environment's maps) by FLIP",
                 "arsim render -o session   (or: arsim render scenarios/indoor.toml -o session --env probe.exr --method sh)")
    _session_options(p, "light the objects with this environment instead of the captured probe", recording=True)
    p.add_argument("--recording", type=_path, metavar="REC",
                   help="replay this recording (any layout, with or without a ground truth) with the scenario's objects "
                        "instead of recording anew")
    p.add_argument("--maps", type=_path, nargs="+", metavar="DIR",
                   help="light the objects with maps baked before (`arsim bake` folders, one per method) instead of the captured probe")
    p.add_argument("--method", choices=sorted(METHODS),
                   help="map method of the objects that name none (default: [render] method, fast)")
    p.add_argument("--key", type=_positive("--key", float), help="Reinhard's key a (default: [render] key, 0.18)")
    p.add_argument("--white", type=_positive("--white", float), help="Reinhard's L_white (default: [render] white, 2.0)")
    p.add_argument("--log-average", action=argparse.BooleanOptionalAction,
                   help="tone-map with Reinhard's log-average luminance (default: [render] log_average, off: the mean)")
    p.add_argument("--every", type=_positive("--every"), default=1, metavar="K",
                   help="render every K-th frame of the AR path (default: 1, all)")
    p.add_argument("--overlay", action=argparse.BooleanOptionalAction,
                   help="draw the overlay: frame time and map state (default: [render] overlay, off)")
    p.set_defaults(run=cmd_render)


def _profile_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "profile", "profile the render loop while it bakes maps tile by tile (thesis 5.1 step 3): per step and frame "
                 "CPU and GL time against a frame budget, a Chrome trace (Perfetto), a timeline plot and profile.md; "
                 "--sweep compares tile policies (the thesis's table 6.6)",
                 "arsim profile -o prof --tile auto   (or: arsim profile scenarios/indoor.toml -o prof --sweep 32,64,128,auto)")
    _session_options(p, "bake from this environment instead of the captured probe")
    p.add_argument("--budget-ms", type=_positive("--budget-ms", float), metavar="X",
                   help="frame budget in ms (default: [profile] budget_ms, 33.3)")
    p.add_argument("--tile", metavar="N|auto", help="tile side baked per frame, or auto (default: [profile] tile, auto)")
    p.add_argument("--sweep", metavar="LIST", help="run each tile policy, e.g. 32,64,128,auto, and tabulate them")
    p.add_argument("--bake", choices=LOOP_METHODS, help="method of the maps baked (default: [profile] bake, accurate)")
    p.add_argument("--max-frames", type=_positive("--max-frames"), metavar="K",
                   help="stop after K frames even if the bake is not complete (default: [profile] max_frames)")
    p.set_defaults(run=cmd_profile)


def _run_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "run", "run a scenario end to end: record (or replay --recording), capture the probe, bake the maps of "
                 "every method it names, run the AR session, evaluate every stage, and write the run directory with "
                 "manifest.json and report/index.html; --baseline compares the frames with a baseline's",
                 "arsim run -o run   (or: arsim run scenarios/indoor.toml -o run --baseline baselines/indoor)")
    p.add_argument("scenario", type=_path, nargs="?", metavar="SCENARIO", help=SCENARIO_HELP)
    _output_option(p, "run directory")
    p.add_argument("--recording", type=_path, metavar="REC", help="replay this recording (`arsim record`) instead of recording anew")
    p.add_argument("--keep-recording", action="store_true",
                   help="keep the recording's frame images in DIR/recording (about 0.45 MB each; left out by default, "
                        "as `arsim record DIR/scenario.toml` makes them again byte-identical; a recording replayed with "
                        "--recording is never copied into DIR)")
    p.add_argument("--baseline", type=_path, metavar="DIR", help="compare the run's frames with this baseline (a run directory)")
    p.add_argument("--update-baseline", action="store_true", help="write the run's frames as the baseline DIR instead of comparing")
    p.add_argument("--max-flip", type=_max_flip, default=DEFAULT_MAX_FLIP, metavar="X",
                   help=f"with --baseline: largest mean FLIP a frame may have (default {DEFAULT_MAX_FLIP:g})")
    _cache_options(p)
    p.set_defaults(run=cmd_run)


def _cache_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--cache", type=_path, metavar="DIR",
                   help="reuse and keep each stage's outputs in this cache folder (default: $ARSIM_CACHE, else the "
                        "user's cache folder, e.g. ~/.cache/arsim)")
    p.add_argument("--no-cache", action="store_true", help="compute every stage; read and write no cache")


def _cache_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "cache", "the run cache of `arsim run` and `arsim batch`: what it holds (info), or empty it (clear)",
                 "arsim cache info   (or: arsim cache clear, arsim cache info --cache DIR)")
    p.add_argument("action", choices=("info", "clear"), help="info: entries and size per stage; clear: remove every entry")
    p.add_argument("--cache", type=_path, metavar="DIR", help="the cache folder (default: $ARSIM_CACHE, else the user's cache folder)")
    p.add_argument("--json", action="store_true", help="info as JSON")
    p.set_defaults(run=cmd_cache)


def _batch_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "batch", "run many scenarios end to end in parallel processes (or as tasks on a Ray cluster) and write "
                 "one summary of all their metrics and regressions (summary.md, summary.html, summary.json)",
                 "arsim batch scenarios/*.toml -o batch --workers 2   (or: ... --ray auto, --baselines baselines)")
    p.add_argument("scenarios", type=_path, nargs="+", metavar="SCENARIO", help="scenario .toml files, or bundled scenarios' names")
    _output_option(p, "batch folder: a run directory per scenario")
    p.add_argument("--workers", type=_positive("--workers"), default=1, metavar="N", help="runs at once on this machine (default 1)")
    p.add_argument("--ray", metavar="ADDRESS", help="run each scenario as a task on the Ray cluster at ADDRESS (host:port, or auto)")
    p.add_argument("--baselines", type=_path, metavar="DIR", help="compare each run's frames with DIR/<scenario name>")
    p.add_argument("--max-flip", type=_max_flip, default=DEFAULT_MAX_FLIP, metavar="X",
                   help=f"with --baselines: largest mean FLIP a frame may have (default {DEFAULT_MAX_FLIP:g})")
    _cache_options(p)
    p.set_defaults(run=cmd_batch)


def _diff_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "diff", "visual regression: compare two images, or the frames of two run directories matched by name, "
                 "by FLIP (mean and 99th percentile), PSNR and the largest difference, and two runs' figures (every "
                 "metric of metrics.json, both values and the change); writes a heatmap per frame that differs, "
                 "metrics.md and an HTML page; exit status 1 when a frame's mean FLIP exceeds --max-flip or a figure "
                 "got worse beyond its tolerance",
                 "arsim diff baseline run -o diff --max-flip 0.001   (or: arsim diff a.png b.png)")
    p.add_argument("a", type=_path, metavar="A", help="the reference: an image, a run directory or a folder of frames")
    p.add_argument("b", type=_path, metavar="B", help="what is compared with it (the same kind as A)")
    _output_option(p, "write heatmaps/, diff.json and index.html into this folder", required=False)
    p.add_argument("--max-flip", type=_max_flip, default=DEFAULT_MAX_FLIP, metavar="X",
                   help=f"largest mean FLIP a frame may have (default {DEFAULT_MAX_FLIP:g}: any difference fails)")
    p.add_argument("--gate-times", action="store_true",
                   help="two runs: let times and speeds that got worse beyond their tolerance fail the diff too "
                        "(by default they are listed only: they differ from run to run on any machine)")
    p.set_defaults(run=cmd_diff)


def _validate_parser(sub: argparse._SubParsersAction) -> None:
    p = _command(sub, "validate", "check a scenario file and print it as resolved (defaults filled in, paths found)",
                 "arsim validate scenarios/indoor.toml")
    p.add_argument("scenario", type=_path, nargs="?", metavar="SCENARIO", help=SCENARIO_HELP)
    p.set_defaults(run=cmd_validate)



def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="arsim",
        description="arsim: a simulator of a mobile AR app that captures real-world light and renders virtual objects with it.",
        epilog="example:\n  arsim info assets/envmaps/city.exr\n\nrun 'arsim COMMAND --help' for the options of a command.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"arsim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for add in (_info_parser, _convert_parser, _bake_parser, _bases_parser, _prt_parser, _estimate_parser, _compare_methods_parser, _record_parser,
                _capture_parser, _export_parser, _render_parser, _profile_parser, _run_parser, _batch_parser, _cache_parser, _diff_parser, _validate_parser):
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        progress_mode()  # a bad $ARSIM_PROGRESS stops here, before any work
        return args.run(args)
    except ArsimError as exc:
        print(f"arsim {args.command}: error: " + " ".join(str(exc).splitlines()), file=sys.stderr)  # one line, always
        return 2
    except OSError as exc:  # the disk full, a folder made read-only mid-run: one line naming the path
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"arsim {args.command}: error: {where}{exc.strerror or exc}; check the path, the free space and the "
              "permissions, then run again", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"arsim {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
