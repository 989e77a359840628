"""Recordings: what a phone would have logged during the capture sweep, written for replay and for
other tools to read, and read back with checks that explain what is wrong.

A recording folder holds:
  meta.json          format version, seed, camera intrinsics, camera-to-device rotation, the scenario
  frames/NNNNNN.png  8-bit RGB frames;  frames.csv: t_ns, exposure_ns, iso, file
  burst/NN.png       a bracketed burst around the auto-exposure, looking at the horizon (for response calibration);
                     burst.csv: exposure_ns, iso, file
  imu.csv            t_ns, sensor, x, y, z   (gyroscope rad/s, accelerometer m/s², magnetometer µT)
  orientation.csv    t_ns, qx, qy, qz, qw    (the fused device-to-world orientation the app reads)
  groundtruth.csv    t_ns, px, py, pz, qx, qy, qz, qw  (true device pose at every gyroscope sample; optional:
                     a real recording has none, and what is measured against it is left out)
  ar/                the AR path ([ar] enabled): a recording of its own in the same layout (no burst),
                     its meta.json adding the table, the tag and its world corners
  frames_not_kept.json  only where `arsim run` left the frame images out (README: Run outputs and disk):
                     how many, their bytes and digest, and how to make them again
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import hashlib
import io
import json
import math
import os
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from arsim import __version__
from arsim.core.conventions import CameraIntrinsics
from arsim.core.errors import ArsimError
from arsim.core.files import clear_files, is_temporary, write_text_atomic
from arsim.core.png import VIDEO_SUFFIX, FrameVideo, frame_file, video_frame, video_frame_name, video_size, write_frame_png
from arsim.scenario import Scenario, scenario_to_toml
from arsim.scenario.environment import load_environment
from arsim.sensors.camera import AutoExposure, ResponseCurve, SensorSettings, noise_key
from arsim.sensors.fusion import mahony, yaw_error_deg
from arsim.sensors.imu import SensorStream, sensor_model, simulate_imu
from arsim.sensors.table import Table
from arsim.sensors.trajectory import ARPath, CaptureSweep, Trajectory, camera_mount
from arsim.sensors.views import CameraRenderer

if TYPE_CHECKING:
    from arsim.sensors.formats.common import Photometric

FORMAT = "arsim-recording/1"
MAX_PENDING_FRAMES = 8
SENSORS = ("gyroscope", "accelerometer", "magnetometer")


def capture_sweep(scenario: Scenario) -> CaptureSweep:
    c = scenario.capture
    return CaptureSweep(c.duration_s, c.turns, c.pitch_from_deg, c.pitch_to_deg, c.roll_wobble_deg, c.sway_m)


def camera_intrinsics(scenario: Scenario) -> CameraIntrinsics:
    cam = scenario.device.camera
    return CameraIntrinsics.from_fov(cam.width, cam.height, cam.hfov_deg, cam.k1, cam.k2)


def _csv(header: list[str], rows) -> str:
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return out.getvalue()


def _csv_formatted(header: list[str], row_format: str, rows) -> str:
    return ",".join(header) + "\n" + "".join(row_format % row + "\n" for row in rows)


BURST_METERING_FRAMES = 8  # unrecorded frames the burst's auto-exposure takes to settle on its view
# The upper codes a burst must reach for the capture's response calibration to set its scale there (it
# fits codes near 255 and refuses a burst without them): a burst none of whose brightest frames has this
# fraction of its pixels in this range makes the app look for a better view.
BURST_UPPER_CODES, BURST_MIN_UPPER = (200, 250), 0.001
BURST_CANDIDATES = 24  # views along the sweep the app tries when the first burst view is too dark


def _burst_settings(camera: CameraRenderer, view: Rotation, scenario: Scenario, response: ResponseCurve) -> list[tuple]:
    """The burst's (exposure_s, iso) for a view: the auto-exposure settles on the view first (unrecorded frames,
    no latency), then the frames step by burst_step around its exposure (time first, then ISO, within the
    sensor's limits; shifted down where the top would pass them)."""
    capture, sensor = scenario.capture, camera.sensor
    metering = AutoExposure(dataclasses.replace(sensor, latency_frames=0, convergence=1.0), response)
    for k in range(BURST_METERING_FRAMES):
        used = metering.next_frame_settings()
        metering.update(camera.capture(view, *used, noise_key(scenario.run.seed, "burst", 1000 + k)), used)
    # The bracket is shifted, not cut, where it would pass the sensor's longest product: frames stay distinct.
    longest = sensor.exposure_range_s[1] * sensor.iso_range[1] / sensor.base_iso
    top = min(metering.product * capture.burst_step ** ((capture.burst_frames - 1) / 2), longest)
    return [metering.settings(top / capture.burst_step ** (capture.burst_frames - 1 - k)) for k in range(capture.burst_frames)]


def _reaches_upper_codes(frame: np.ndarray) -> float:
    lo, hi = BURST_UPPER_CODES
    return float(np.mean((frame >= lo) & (frame <= hi)))


def _write_burst(out_dir: Path, camera: CameraRenderer, views: Rotation, scenario: Scenario,
                 response: ResponseCurve) -> list[tuple]:
    """A bracketed burst of one view (before the sweep), as phones take for HDR, of views[0]; where none of
    that burst's frames reaches the upper codes (a dark room seen at the horizon: the response could not be
    calibrated from it), of the view among views[1:] whose brightest burst frame has the most pixels there,
    as an app that brackets until the codes span the range does. Returns the burst.csv rows."""
    def upper(view, settings):
        return max(_reaches_upper_codes(camera.capture(view, *used, noise_key(scenario.run.seed, "burst", 2000 + k)))
                   for k, used in enumerate(settings[-3:]))

    view, settings = views[0], _burst_settings(camera, views[0], scenario, response)
    if len(views) > 1 and upper(view, settings) < BURST_MIN_UPPER:
        tried = [(v, _burst_settings(camera, v, scenario, response)) for v in views[1:]]
        view, settings = max(reversed(tried), key=lambda t: upper(*t))  # (the last of equals)
    (out_dir / "burst").mkdir(exist_ok=True)
    clear_files(out_dir / "burst", "*.png")  # an earlier recording's burst, a killed writer's temp file
    rows = []
    for k, (exposure, iso) in enumerate(settings):
        frame = camera.capture(view, exposure, iso, noise_key(scenario.run.seed, "burst", k))
        name = f"burst/{k:02d}.png"
        write_frame_png(out_dir / name, frame)
        rows.append((int(round(exposure * 1e9)), round(iso, 3), name))
    return rows


@dataclass(frozen=True)
class RecordSummary:
    frames: int
    duration_s: float
    final_yaw_error_deg: float
    ar_frames: int = 0


def frame_count(trajectory: Trajectory, fps: float) -> int:
    """Frames at t = 0, 1/fps, ... up to the trajectory's end."""
    return int(math.floor(trajectory.duration * fps)) + 1


def ar_path(scenario: Scenario) -> ARPath:
    a = scenario.ar
    for where, section in (("[ar]", a), *(("[[ar.look_away]]", w) for w in a.look_away)):
        if problem := section.rules():  # (the schema applies them at load; a scenario built in code meets them here)
            raise ArsimError(f"{where} {problem}")
    return ARPath(a.duration_s, a.laps, a.near_m, a.far_m, a.shake_deg, tuple((w.start_s, w.end_s) for w in a.look_away))


@dataclass(frozen=True)
class _Segment:
    """One stretch of a recording: a trajectory, what the camera sees along it, where it is written."""

    name: str  # "capture" or "ar"; also the noise stream of its frames
    trajectory: Trajectory
    table: Table | None
    imu_seed: int  # the IMU streams' generator key, distinct per segment
    burst: bool
    folder: str  # relative to the recording ("" for the recording's own files)
    bracket_ev: tuple[float, ...] = (0.0,)  # exposure offsets the frames cycle through (0: metered)


def recording_segments(scenario: Scenario) -> list[_Segment]:
    """What `record` will write; raises ArsimError for settings that do not fit together (call it
    before creating any output)."""
    SensorSettings.of(scenario.device.camera).check()
    bracket = scenario.capture.bracket_ev
    if not bracket or bracket[0] != 0.0:
        raise ArsimError(f"[capture] bracket_ev = {list(bracket)}: the first offset must be 0 (the metered exposure), "
                         "e.g. [0.0, -7.0, -14.0]")
    segments = [_Segment("capture", capture_sweep(scenario), None, 1, True, "", bracket)]
    if scenario.ar.enabled:
        segments.append(_Segment("ar", ar_path(scenario), Table.of(scenario.ar), 4, False, "ar"))
    return segments


def record(scenario: Scenario, out_dir: Path, progress: Callable[[float], None] = lambda f: None,
           compact: bool = False) -> RecordSummary:
    """Synthesise the capture sweep of a scenario into out_dir (created if missing) and, when [ar] is
    enabled, the AR path with the table and tag into out_dir/ar (a recording of its own). Deterministic:
    the same scenario and seed give byte-identical files. compact: each segment's frames in one lossless video
    (frames.mkv: core.png.FrameVideo) instead of a PNG per frame; the same pixels."""
    cam = scenario.device.camera
    segments = recording_segments(scenario)
    counts = [frame_count(s.trajectory, cam.fps) for s in segments]
    probe = load_environment(scenario.environment)
    # The capture's meta.json points to the other segments' folders.
    links = {"ar_recording": s.folder for s in segments if s.name == "ar"}
    yaw = []
    for k, segment in enumerate(segments):
        done, total = sum(counts[:k]), sum(counts)
        yaw.append(_record_segment(scenario, probe, segment, out_dir / segment.folder,
                                   lambda f: progress((done + f * counts[k]) / total),
                                   links if segment.name == "capture" else {}, compact))
    return RecordSummary(counts[0], segments[0].trajectory.duration, yaw[0], counts[1] if len(counts) > 1 else 0)


def _record_segment(scenario: Scenario, probe: np.ndarray, segment: _Segment, out_dir: Path,
                    progress: Callable[[float], None], extra_meta: dict, compact: bool = False) -> float:
    """Write one segment's files; returns the fused yaw error at its end (degrees)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "frames").mkdir(exist_ok=True)
    clear_files(out_dir / "frames", "*.png")  # an earlier recording's frames, a killed writer's temp file
    clear_files(out_dir, "frames" + VIDEO_SUFFIX + "*")  # (an earlier compact recording's video and its checksum)
    trajectory = segment.trajectory
    camera = camera_intrinsics(scenario)
    cam = scenario.device.camera
    mount = camera_mount(scenario.device.camera_misalignment_deg)
    # Independent streams per purpose, so adding frames does not change the IMU and vice versa (the
    # camera's noise is hashed from seed, stream and frame index: camera.noise_key).
    rng_imu = np.random.default_rng([scenario.run.seed, segment.imu_seed])
    device = scenario.device
    streams = simulate_imu(trajectory, rng_imu, sensor_model(device.gyroscope), sensor_model(device.accelerometer),
                           sensor_model(device.magnetometer))
    t_fused, fused = mahony(streams, trajectory.orientation([0.0])[0], scenario.capture.fusion)
    truth = trajectory.orientation(t_fused / 1e9)

    response = ResponseCurve(cam.response, cam.gamma, cam.contrast)
    renderer = CameraRenderer(probe, camera, SensorSettings.of(cam), response, table=segment.table)
    # The burst looks where the sweep passes the horizon (mid-sweep): sky and ground, the widest range; other
    # views along the sweep where that one is too dark.
    candidates = np.concatenate([[trajectory.duration / 2], np.linspace(0.0, trajectory.duration, BURST_CANDIDATES)])
    burst_views = trajectory.camera_orientation(candidates, mount)
    burst_rows = (_write_burst(out_dir, renderer, burst_views, scenario, response)
                  if segment.burst else [])
    rows = _write_frames(scenario, segment, renderer, response, mount, out_dir, progress, compact)
    if compact and not any((out_dir / "frames").iterdir()):
        (out_dir / "frames").rmdir()
    renderer.release()

    write_text_atomic(out_dir / "frames.csv", _csv(FRAMES_HEADER, rows))
    write_text_atomic(out_dir / "burst.csv", _csv(BURST_HEADER, burst_rows))
    _write_streams(out_dir, streams, t_fused, fused, trajectory.position(t_fused / 1e9), truth)
    meta = _segment_meta(scenario, segment, camera, mount, renderer.table_light)
    write_text_atomic(out_dir / "meta.json", json.dumps(meta | extra_meta, indent=2) + "\n")
    return float(yaw_error_deg(fused[-1:], truth[-1:])[0])


def _write_frames(scenario: Scenario, segment: _Segment, renderer, response, mount, out_dir: Path,
                  progress: Callable[[float], None], compact: bool = False) -> list[tuple]:
    """The segment's frames under auto-exposure (bracketed ones at the metered exposure times 2^ev),
    rendered and written as PNG into out_dir/frames (compact: into the video out_dir/frames.mkv); returns
    frames.csv's rows."""
    cam = scenario.device.camera
    sensor = SensorSettings.of(cam)
    ae = AutoExposure(sensor, response)
    trajectory = segment.trajectory
    n_frames = frame_count(trajectory, cam.fps)
    rows = []
    times = np.arange(n_frames) / cam.fps
    views, positions = trajectory.camera_orientation(times, mount), trajectory.position(times)
    video_name = "frames" + VIDEO_SUFFIX
    with contextlib.ExitStack() as stack:
        writers = stack.enter_context(ThreadPoolExecutor(2))  # PNG encoding releases the GIL: overlap it with rendering
        video = None
        if compact:
            video = stack.enter_context(FrameVideo(out_dir / video_name, cam.width, cam.height, cam.fps))
        pending: deque = deque()
        for k in range(n_frames):
            used = ae.next_frame_settings()
            # Bracketed frames (for highlights) take the metered exposure times 2^ev; only metered
            # frames steer the auto-exposure.
            ev = segment.bracket_ev[k % len(segment.bracket_ev)]
            if ev:
                used = ae.settings(used[0] * used[1] / sensor.base_iso * 2.0**ev)
            frame = renderer.capture(views[k], *used, noise_key(scenario.run.seed, segment.name, k), positions[k])
            if not ev:
                ae.update(frame, used)
            if video is not None:
                video.write(frame)
                file = video_frame_name(video_name, k)
            else:
                name = f"{k:06d}.png"
                pending.append(writers.submit(write_frame_png, out_dir / "frames" / name, frame))
                file = f"frames/{name}"
            while len(pending) > MAX_PENDING_FRAMES:  # bounded: frames waiting to be written hold memory
                pending.popleft().result()
            rows.append((int(round(times[k] * 1e9)), int(round(used[0] * 1e9)), round(used[1], 3), file))
            progress((k + 1) / n_frames)
        for future in pending:
            future.result()
    return rows


def _write_streams(out_dir: Path, streams: dict, t_fused: np.ndarray, fused, device_positions: np.ndarray, truth) -> None:
    """imu.csv, orientation.csv (the fusion's) and groundtruth.csv (positions and orientations at the fusion's
    times)."""
    # Many thousand rows: formatted from Python floats in one pass (9 decimals, as nanoseconds are
    # the time unit and 1e-9 is below every sensor's resolution).
    imu = sorted(((t, name, *v) for name in SENSORS
                  for t, v in zip(streams[name].t_ns.tolist(), streams[name].values.tolist())), key=lambda r: (r[0], r[1]))
    write_text_atomic(out_dir / "imu.csv", _csv_formatted(["t_ns", "sensor", "x", "y", "z"], "%d,%s" + ",%.9f" * 3, imu))
    write_text_atomic(out_dir / "orientation.csv", _csv_formatted(
        ["t_ns", "qx", "qy", "qz", "qw"], "%d" + ",%.9f" * 4, zip(t_fused.tolist(), *fused.as_quat().T.tolist())))
    write_text_atomic(out_dir / "groundtruth.csv", _csv_formatted(
        ["t_ns", "px", "py", "pz", "qx", "qy", "qz", "qw"], "%d" + ",%.9f" * 7,
        zip(t_fused.tolist(), *device_positions.T.tolist(), *truth.as_quat().T.tolist())))


def _segment_meta(scenario: Scenario, segment: _Segment, camera, mount, table_light) -> dict:
    """meta.json's keys: the format, the camera, its mount, the fusion, the scenario, and the table."""
    cam = scenario.device.camera
    meta = {
        "format": FORMAT,
        "arsim_version": __version__,
        "segment": segment.name,
        "seed": scenario.run.seed,
        "duration_s": segment.trajectory.duration,
        "camera": {"width": camera.width, "height": camera.height, "fx": camera.fx, "fy": camera.fy,
                   "cx": camera.cx, "cy": camera.cy, "k1": camera.k1, "k2": camera.k2, "fps": cam.fps},
        "camera_to_device": mount.as_matrix().tolist(),
        "fusion": scenario.capture.fusion,
        "scenario_toml": scenario_to_toml(scenario, portable=True),  # (bundled assets by name: the recording moves)
    }
    if segment.table is not None:
        t = segment.table
        meta["table"] = {"tag_family": t.tag_family, "tag_id": t.tag_id, "tag_size_m": t.tag_size_m,
                         "tag_corners_world": t.tag_corners_world().tolist(), "size_m": list(t.size_m),
                         "albedo": list(t.albedo), "light": [float(v) for v in table_light]}
    return meta


# ----------------------------------------------------------------------------------------------------
# Reading a recording back


@dataclass(frozen=True)
class Recording:
    folder: Path
    meta: dict
    frames: list[dict]  # t_ns, exposure_ns, iso, file
    burst: list[dict]  # exposure_ns, iso, file
    imu: dict[str, SensorStream]
    orientation: tuple[np.ndarray, Rotation]
    groundtruth: tuple[np.ndarray, np.ndarray, Rotation] | None  # None: no groundtruth.csv (a real recording)
    # a camera's photometric calibration where the recording carries one (TUM-VI's): the capture uses it
    # instead of calibrating the response from the burst (README: Recordings in standard layouts)
    photometric: Photometric | None = None


# meta.json as a recording declares it (README: Recording format): key -> (type, what it must hold);
# a type of None means any JSON value. "table" only in an AR path's recording; the keys in META_OPTIONAL may be
# left out (a recording arsim did not synthesise: sensors.frames.recording_scenario says what stands in for them).
_NUMBER = (int, float)
META_SCHEMA = {
    "format": (str, lambda v: v == FORMAT, f"{FORMAT}"),
    "seed": (int, lambda v: v >= 0, "an integer from 0"),
    "duration_s": (_NUMBER, lambda v: 0 < v < 1e9, "a positive number of seconds"),
    "camera": (dict, lambda v: _camera_problem(v) is None, "the camera (width, height, fx, fy, cx, cy, k1, k2, fps)"),
    "camera_to_device": (list, lambda v: _rotation_problem(v) is None, "a 3 x 3 rotation matrix"),
    "fusion": (str, lambda v: True, "the fusion's name"),
    "scenario_toml": (str, lambda v: True, "the scenario as TOML text"),
}
META_OPTIONAL = frozenset({"scenario_toml"})
_CAMERA = {"width": (1, 1 << 15), "height": (1, 1 << 15), "fx": (1e-3, 1e6), "fy": (1e-3, 1e6), "cx": (-1e6, 1e6),
           "cy": (-1e6, 1e6), "k1": (-1.0, 1.0), "k2": (-1.0, 1.0), "fps": (1e-3, 1e4)}


def _camera_problem(cam: dict) -> str | None:
    for key, (lo, hi) in _CAMERA.items():
        v = cam.get(key)
        if isinstance(v, bool) or not isinstance(v, int if key in ("width", "height") else _NUMBER):
            return f"camera.{key} is {v!r}, not {'an integer' if key in ('width', 'height') else 'a number'}"
        if not lo <= v <= hi:
            return f"camera.{key} = {v} is out of range: {lo:g} to {hi:g}"
    return None


def _rotation_problem(m: list) -> str | None:
    try:
        a = np.array(m, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        return "not a matrix of numbers"
    if a.shape != (3, 3) or not np.isfinite(a).all() or not np.allclose(a @ a.T, np.eye(3), atol=1e-6):
        return "not a 3 x 3 rotation"
    return None


def check_meta(meta, path: Path) -> None:
    """meta.json against META_SCHEMA: one ArsimError naming the key and what it must hold."""
    if not isinstance(meta, dict):
        raise ArsimError(f"{path}: holds a JSON {type(meta).__name__}, not an object; give a recording's meta.json")
    if meta.get("format") != FORMAT:
        raise ArsimError(f"{path}: format {meta.get('format')!r} is not known; this arsim reads {FORMAT}")
    for key, (kind, ok, what) in META_SCHEMA.items():
        if key not in meta:
            if key in META_OPTIONAL:
                continue
            raise ArsimError(f"{path}: lacks {key!r} ({what}); record again")
        v = meta[key]
        if isinstance(v, bool) or not isinstance(v, kind) or not ok(v):
            detail = (_camera_problem(v) if key == "camera" and isinstance(v, dict) else
                      _rotation_problem(v) if key == "camera_to_device" and isinstance(v, list) else None)
            raise ArsimError(f"{path}: {key} is not {what}" + (f" ({detail})" if detail else f": {str(v)[:60]!r}"))
    table = meta.get("table")
    if table is not None:
        ok = (isinstance(table, dict) and isinstance(table.get("tag_family"), str) and type(table.get("tag_id")) is int
              and isinstance(table.get("tag_size_m"), _NUMBER) and 0 < table["tag_size_m"] < 100
              and np.shape(table.get("tag_corners_world")) == (4, 3))
        if not ok:
            raise ArsimError(f"{path}: table is not the tag's description (tag_family, tag_id, tag_size_m, "
                             "tag_corners_world); record again")


def _read_csv(path: Path, header: list[str]) -> list[list[str]]:
    """A recording's CSV: its header as expected, every row as long as the header."""
    if not path.is_file():
        raise ArsimError(f"{path}: missing from the recording (or not a file); record it again")
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except UnicodeDecodeError:
        raise ArsimError(f"{path}: is not UTF-8 text; record it again") from None
    except (OSError, csv.Error) as exc:
        raise ArsimError(f"{path}: cannot be read ({getattr(exc, 'strerror', None) or exc}); record it again") from None
    if not rows or rows[0] != header:
        raise ArsimError(f"{path}: header is {rows[0] if rows else 'missing'}, expected {','.join(header)}")
    for k, row in enumerate(rows[1:], 2):
        if len(row) != len(header):
            raise ArsimError(f"{path}: line {k} has {len(row)} fields, expected {len(header)} ({','.join(header)})")
    return rows[1:]


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


# A recording whose frame images were left out (`arsim run` without --keep-recording): its small files stay, and
# this file in each segment's folder says what is missing and how to make it again, byte for byte.
NOT_KEPT = "frames_not_kept.json"
FRAMES_HEADER = ["t_ns", "exposure_ns", "iso", "file"]
BURST_HEADER = ["exposure_ns", "iso", "file"]


def segment_folders(folder: Path) -> list[Path]:
    """A recording's folder and its other segments' (the AR path's, which its meta.json names)."""
    folders = [Path(folder)]
    try:
        sub = json.loads((folder / "meta.json").read_text(encoding="utf-8")).get("ar_recording")
    except (OSError, ValueError, AttributeError):
        sub = None
    if isinstance(sub, str) and (folder / sub / "meta.json").is_file():
        folders.append(folder / sub)
    return folders


def image_files(segment: Path) -> list[str]:
    """The image files a segment's frames.csv and burst.csv name (paths under the segment's folder; a compact
    recording's video once)."""
    names = ([row[3] for row in _read_csv(segment / "frames.csv", FRAMES_HEADER)]
             + [row[2] for row in _read_csv(segment / "burst.csv", BURST_HEADER)])
    return list(dict.fromkeys(frame_file(Path(name)).as_posix() for name in names))


def images_digest(hashes: dict[str, str]) -> str:
    """One sha256 over images' paths and their sha256 (hashes: path -> sha256): equal for byte-identical images."""
    h = hashlib.sha256()
    for rel in sorted(hashes):
        h.update(f"{rel}\0{hashes[rel]}\0".encode())
    return h.hexdigest()


def recording_image_paths(folder: Path) -> list[str]:
    """Every image of a recording, its segments' frames and burst: paths under folder."""
    return [(segment / name).relative_to(folder).as_posix() for segment in segment_folders(folder)
            for name in image_files(segment)]


def recording_images(folder: Path) -> dict[str, str]:
    """Every image of a recording: path under folder -> sha256."""
    hashes = {}
    for rel in recording_image_paths(folder):
        with open(folder / rel, "rb") as f:
            hashes[rel] = hashlib.file_digest(f, "sha256").hexdigest()
    return hashes


def leave_out_images(folder: Path, hashes: dict[str, str], note: dict) -> dict:
    """The recording's frame images removed (its CSVs, IMU streams, truth, meta.json and plots stay), and in each
    segment a NOT_KEPT file saying how many, their bytes and digest, with note (what makes them again: the
    scenario file relative to the recording's folder, under "scenario"). hashes: every image's path under folder
    -> sha256. Returns the totals: files, bytes, sha256 (images_digest of all of them)."""
    total = {"files": 0, "bytes": 0}
    for segment in segment_folders(folder):
        names = image_files(segment)
        rels = [(segment / name).relative_to(folder).as_posix() for name in names]
        size = sum((folder / rel).stat().st_size for rel in rels)
        prefix = segment.relative_to(folder).as_posix()
        up = "../" * (0 if prefix == "." else len(Path(prefix).parts))
        record = {"files": len(rels), "bytes": size,
                  "sha256": images_digest({name: hashes[rel] for name, rel in zip(names, rels)}),
                  **note, "scenario": up + note["scenario"]}
        write_text_atomic(segment / NOT_KEPT, json.dumps(record, indent=2) + "\n")
        for rel in rels:
            (folder / rel).unlink()
        for sub in ("frames", "burst"):
            if (segment / sub).is_dir() and not any((segment / sub).iterdir()):
                (segment / sub).rmdir()
        total["files"] += len(rels)
        total["bytes"] += size
    return total | {"sha256": images_digest({rel: hashes[rel] for rel in hashes})}


def _not_kept_problem(folder: Path) -> str | None:
    """Where a recording's images were left out by `arsim run`: what is missing and how to make it again."""
    path = folder / NOT_KEPT
    if not path.is_file():
        return None
    try:
        note = json.loads(path.read_text(encoding="utf-8"))
        files, size, scenario = int(note["files"]), int(note["bytes"]), str(note["scenario"])
    except (OSError, ValueError, KeyError, TypeError):
        return f"{folder}: its frame images were left out ({path} says so, but cannot be read); record the scenario again"
    where = os.path.normpath(folder / scenario)
    return (f"{folder}: its {files} frame images ({size / 1e6:.1f} MB) were not kept by `arsim run` (they are kept with "
            f"--keep-recording); make them again, byte-identical, with `arsim record {where} -o REC` and give REC instead")


def _check_frames(folder: Path, names: list[str], width: int, height: int) -> None:
    """Each frame's PNG header (_check_frame_header); a compact recording's video: its size, and a frame for
    every index named."""
    videos: dict[Path, int] = {}
    for name in names:
        found = video_frame(folder / name)
        if found is None:
            _check_frame_header(folder / name, width, height)
        else:
            videos[found[0]] = max(videos.get(found[0], -1), found[1])
    for video, last in videos.items():
        w, h, count = video_size(video)
        if (w, h) != (width, height):
            raise ArsimError(f"{video}: is {w} x {h}, the camera's frames are {width} x {height}; record again")
        if count <= last:
            raise ArsimError(f"{video}: holds {count} frames, the CSV names frame {last}; record again")


def _check_frame_header(path: Path, width: int, height: int) -> None:
    """A frame's PNG header read (not its pixels: `arsim info` decodes them): a PNG of the camera's size."""
    try:
        with path.open("rb") as f:
            head = f.read(24)
    except OSError as exc:
        raise ArsimError(f"{path}: cannot be read ({exc.strerror or exc}); record again") from None
    if len(head) < 24 or not head.startswith(PNG_SIGNATURE) or head[12:16] != b"IHDR":
        raise ArsimError(f"{path}: is not a PNG image (empty, truncated or another format); record again")
    w, h = int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    if (w, h) != (width, height):
        raise ArsimError(f"{path}: is {w} x {h}, the camera's frames are {width} x {height}; record again")


def _rotations(path: Path, q: np.ndarray, what: str) -> Rotation:
    """Quaternions (K, 4) as rotations: at least two (they are interpolated), none of zero length."""
    if len(q) < 2:
        raise ArsimError(f"{path}: holds {len(q)} {what}, need at least 2; record again")
    norms = np.linalg.norm(q, axis=1)
    if (norms < 1e-6).any():
        raise ArsimError(f"{path}: line {int(np.flatnonzero(norms < 1e-6)[0]) + 2} has a zero quaternion; record again")
    return Rotation.from_quat(q)


def _numbers(path: Path, rows: list[list[str]], columns: slice) -> np.ndarray:
    if not rows:
        return np.zeros((0, columns.stop - columns.start))
    try:
        values = np.array([[float(v) for v in row[columns]] for row in rows], dtype=np.float64)
    except ValueError as exc:
        raise ArsimError(f"{path}: a value is not a number ({exc})") from None
    if values.size and not np.isfinite(values).all():
        bad = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0]) + 2
        raise ArsimError(f"{path}: line {bad} has a NaN or infinite value")
    return values


def _increasing(path: Path, t_ns: np.ndarray, what: str) -> None:
    back = np.flatnonzero(np.diff(t_ns) <= 0)
    if back.size:
        k = int(back[0])
        raise ArsimError(f"{path}: timestamps of the {what} go backwards after entry {k + 1} "
                         f"({int(t_ns[k])} then {int(t_ns[k + 1])} ns); fix or drop that entry")


def load_recording(folder: Path) -> Recording:
    """Read and check a recording; every problem is one ArsimError naming the file and what to fix."""
    folder = Path(folder)
    if not (folder / "meta.json").exists():
        from arsim.sensors.formats import detect_format, open_recording

        if detect_format(folder) is not None:  # a EuRoC / TUM-VI folder or a ROS 2 bag
            return open_recording(folder)
        raise ArsimError(f"{folder}: not a recording (no meta.json); give a folder written by arsim record")
    try:
        meta = json.loads((folder / "meta.json").read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ArsimError(f"{folder / 'meta.json'}: is not valid JSON ({exc})") from None
    except OSError as exc:
        raise ArsimError(f"{folder / 'meta.json'}: cannot be read ({exc.strerror or exc}); record again") from None
    check_meta(meta, folder / "meta.json")

    path = folder / "frames.csv"
    rows = _read_csv(path, FRAMES_HEADER)
    numbers = _numbers(path, rows, slice(0, 3))
    t_frames = numbers[:, 0].astype(np.int64) if len(rows) else np.zeros(0, np.int64)
    _increasing(path, t_frames, "frames")
    listed = [row[3] for row in rows]
    missing = [name for name in listed if not frame_file(folder / name).exists()]
    if missing and (problem := _not_kept_problem(folder)) is not None:
        raise ArsimError(problem)
    if missing:
        raise ArsimError(f"{path}: {len(missing)} listed frames are missing, first {missing[0]}; record again or drop them from frames.csv")
    extra = sorted({f"frames/{p.name}" for p in (folder / "frames").glob("*.png") if not is_temporary(p)} - set(listed))
    if extra:
        raise ArsimError(f"{folder / 'frames'}: {len(extra)} frames are not in frames.csv, first {extra[0]}; remove them or list them")
    frames = [{"t_ns": int(n[0]), "exposure_ns": int(n[1]), "iso": float(n[2]), "file": f} for n, f in zip(numbers, listed)]
    cam = meta["camera"]
    _check_frames(folder, listed, cam["width"], cam["height"])

    path = folder / "burst.csv"
    rows = _read_csv(path, BURST_HEADER)
    numbers = _numbers(path, rows, slice(0, 2))
    missing = [row[2] for row in rows if not frame_file(folder / row[2]).exists()]
    if missing:
        raise ArsimError(f"{path}: {len(missing)} listed burst frames are missing, first {missing[0]}; record again")
    _check_frames(folder, [row[2] for row in rows], cam["width"], cam["height"])
    burst = [{"exposure_ns": int(n[0]), "iso": float(n[1]), "file": row[2]} for n, row in zip(numbers, rows)]

    path = folder / "imu.csv"
    rows = _read_csv(path, ["t_ns", "sensor", "x", "y", "z"])
    unknown = sorted({row[1] for row in rows} - set(SENSORS))
    if unknown:
        raise ArsimError(f"{path}: unknown sensor {unknown[0]!r}; expected {', '.join(SENSORS)}")
    imu = {}
    for name in SENSORS:
        mine = [row for row in rows if row[1] == name]
        values = _numbers(path, [[row[0], *row[2:]] for row in mine], slice(0, 4))
        t_ns = values[:, 0].astype(np.int64) if len(mine) else np.zeros(0, np.int64)
        _increasing(path, t_ns, name)
        imu[name] = SensorStream(name, t_ns, values[:, 1:] if len(mine) else np.zeros((0, 3)))

    path = folder / "orientation.csv"
    values = _numbers(path, _read_csv(path, ["t_ns", "qx", "qy", "qz", "qw"]), slice(0, 5))
    _increasing(path, values[:, 0].astype(np.int64), "orientations")
    orientation = (values[:, 0].astype(np.int64), _rotations(path, values[:, 1:], "orientations"))
    path = folder / "groundtruth.csv"
    groundtruth = None  # (a real recording has none: what needs it is left out, saying so)
    if path.exists():
        values = _numbers(path, _read_csv(path, ["t_ns", "px", "py", "pz", "qx", "qy", "qz", "qw"]), slice(0, 8))
        _increasing(path, values[:, 0].astype(np.int64), "ground-truth poses")
        groundtruth = (values[:, 0].astype(np.int64), values[:, 1:4], _rotations(path, values[:, 4:], "ground-truth poses"))
    return Recording(folder, meta, frames, burst, imu, orientation, groundtruth)
