"""The EuRoC / ASL folder layout (README: Recordings in standard layouts), written and read.

  mav0/body.yaml                          the body frame B: arsim's device frame (the IMU's axes)
  mav0/cam0/data.csv, data/<t_ns>.png     #timestamp [ns],filename; the frames' PNG files as recorded
  mav0/cam0/sensor.yaml                   T_BS (camera to body), rate_hz, resolution, pinhole intrinsics
                                          [fu, fv, cu, cv], radial-tangential [k1, k2, p1, p2]
  mav0/imu0/data.csv, sensor.yaml         the gyroscope's samples with the accelerometer interpolated to their
                                          times (EuRoC's common timestamps); noise densities and random walks
  mav0/state_groundtruth_estimate0/       the true device pose, quaternion w, x, y, z (when the recording has one)
  arsim/                                  what EuRoC cannot hold, for an exact round trip (a EuRoC reader ignores
                                          it): meta.json (seed, fusion, the scenario, the AR table), frames.csv
                                          (exposure, ISO), imu.csv (the accelerometer and magnetometer as
                                          measured), orientation.csv (the fused orientation), burst.csv, burst/
  ar/                                     the AR path, a EuRoC folder of its own

TUM-VI's additions (tumvi.py) extend it: exposure times and the photometric calibration under dso/cam0, the
ground truth as mav0/mocap0.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import yaml

from arsim.core.errors import ArsimError
from arsim.core.files import write_bytes_atomic, write_text_atomic
from arsim.core.png import png_of_frame
from arsim.sensors.formats.common import (FOREIGN_EXPOSURE_NS, FOREIGN_ISO, Photometric, exact_rotations, extras_meta,
                                          fused_orientation,
                                          imu_streams, layout_meta, merged_imu, recording_of)
from arsim.sensors.imu import SensorStream
from arsim.sensors.recording import (SENSORS, Recording, _camera_problem, _check_frame_header, _csv_formatted,
                                     _rotation_problem)

MAV = "mav0"
EXTRAS = "arsim"
CAM_HEADER = "#timestamp [ns],filename"
IMU_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
              "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
GT_HEADER = ("#timestamp,p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z [],"
             "v_RS_R_x [m s^-1],v_RS_R_y [m s^-1],v_RS_R_z [m s^-1],b_w_RS_S_x [rad s^-1],b_w_RS_S_y [rad s^-1],"
             "b_w_RS_S_z [rad s^-1],b_a_RS_S_x [m s^-2],b_a_RS_S_y [m s^-2],b_a_RS_S_z [m s^-2]")
GROUNDTRUTH = "state_groundtruth_estimate0"


# ----------------------------------------------------------------------------------------------------
# Writing


def yaml_float(x: float) -> str:
    """A float as YAML 1.1 (PyYAML, OpenCV) reads it back exactly: Python's shortest repr, with a '.' before
    an exponent (PyYAML takes 1e-05 for a string)."""
    text = repr(float(x))
    if "e" in text and "." not in text.split("e")[0]:
        base, exp = text.split("e")
        text = f"{base}.0e{exp}"
    return text


def _yaml_list(values) -> str:
    return "[" + ", ".join(yaml_float(v) for v in values) + "]"


def _t_bs(rotation: np.ndarray) -> str:
    m = np.eye(4)
    m[:3, :3] = rotation
    rows = [", ".join(yaml_float(v) for v in row) for row in m]
    return "T_BS:\n  cols: 4\n  rows: 4\n  data: [" + ",\n         ".join(rows) + "]\n"


def camera_yaml(meta: dict) -> str:
    cam = meta["camera"]
    return ("# General sensor definitions.\nsensor_type: camera\ncomment: arsim camera (the phone's, simulated)\n\n"
            "# Sensor extrinsics wrt. the body-frame (arsim's device frame; no lever arm).\n"
            + _t_bs(np.array(meta["camera_to_device"]))
            + f"\n# Camera specific definitions.\nrate_hz: {yaml_float(cam['fps'])}\n"
            f"resolution: [{cam['width']}, {cam['height']}]\ncamera_model: pinhole\n"
            f"intrinsics: {_yaml_list([cam['fx'], cam['fy'], cam['cx'], cam['cy']])} #fu, fv, cu, cv\n"
            f"distortion_model: radial-tangential\n"
            f"distortion_coefficients: {_yaml_list([cam['k1'], cam['k2'], 0.0, 0.0])}\n")


def _imu_noise(meta: dict) -> dict:
    """The IMU's noise figures from the recording's scenario, where it has one."""
    if "scenario_toml" not in meta:
        return {}
    from arsim.scenario.loader import parse_scenario

    device = parse_scenario(meta["scenario_toml"], "meta.json").device
    return {"gyroscope_noise_density": (device.gyroscope.noise_density, "[ rad / s / sqrt(Hz) ]   ( gyro \"white noise\" )"),
            "gyroscope_random_walk": (device.gyroscope.bias_random_walk, "[ rad / s^2 / sqrt(Hz) ] ( gyro bias diffusion )"),
            "accelerometer_noise_density": (device.accelerometer.noise_density, "[ m / s^2 / sqrt(Hz) ]   ( accel \"white noise\" )"),
            "accelerometer_random_walk": (device.accelerometer.bias_random_walk, "[ m / s^3 / sqrt(Hz) ]  ( accel bias diffusion )"),
            "rate_hz": (device.gyroscope.rate_hz, "")}


def imu_yaml(meta: dict) -> str:
    noise = _imu_noise(meta)
    text = ("#Default imu sensor yaml file\nsensor_type: imu\ncomment: arsim IMU (the phone's gyroscope and "
            "accelerometer, simulated)\n\n# Sensor extrinsics wrt. the body-frame.\n" + _t_bs(np.eye(3)))
    if noise:
        text += f"rate_hz: {yaml_float(noise.pop('rate_hz')[0])}\n\n# inertial sensor noise model parameters (static)\n"
        text += "".join(f"{k}: {yaml_float(v)}     # {unit}\n" for k, (v, unit) in noise.items())
    return text


BODY_YAML = ("# The body frame B: arsim's device frame, the IMU's axes (x right, y up, z out of the screen).\n"
             "comment: arsim device\n")
GT_YAML = ("sensor_type: visual-inertial\ncomment: arsim's true device pose (the simulation's ground truth)\n"
           + _t_bs(np.eye(3)))


def _lines(header: str, fmt: str, rows) -> str:
    return header + "\n" + "".join(fmt % tuple(row) + "\n" for row in rows)


def groundtruth_rows(rec: Recording, full: bool) -> list:
    """Rows of EuRoC's state estimate (full: velocity by central differences of the positions; the IMU's
    biases, which arsim does not record, 0) or of TUM-VI's mocap0 (the pose alone); quaternions w, x, y, z."""
    t, p, q = rec.groundtruth
    xyzw = q.as_quat()
    rows = np.column_stack([p, xyzw[:, 3:], xyzw[:, :3]])
    if full:
        v = np.gradient(p, t.astype(np.float64) / 1e9, axis=0) if len(t) > 1 else np.zeros_like(p)
        rows = np.column_stack([rows, v, np.zeros((len(t), 6))])
    return [(int(a), *b) for a, b in zip(t.tolist(), rows.tolist())]


def write_euroc(rec: Recording, out: Path, groundtruth_folder: str | None = GROUNDTRUTH) -> None:
    """rec in EuRoC's layout into out (created if missing). groundtruth_folder: where the truth goes (TUM-VI's
    mocap0 holds the pose alone; None: not written)."""
    mav = out / MAV
    for sub in ("cam0/data", "imu0", EXTRAS):
        (mav / sub if sub != EXTRAS else out / EXTRAS).mkdir(parents=True, exist_ok=True)
    write_text_atomic(mav / "body.yaml", BODY_YAML)
    names = []
    for f in rec.frames:
        name = f"{f['t_ns']}.png"
        write_bytes_atomic(mav / "cam0" / "data" / name, png_of_frame(rec.folder / f["file"]))
        names.append((f["t_ns"], name))
    write_text_atomic(mav / "cam0" / "data.csv", _lines(CAM_HEADER, "%d,%s", names))
    write_text_atomic(mav / "cam0" / "sensor.yaml", camera_yaml(rec.meta))
    t, gyro, accel = merged_imu(rec.imu)
    write_text_atomic(mav / "imu0" / "data.csv",
                      _lines(IMU_HEADER, "%d" + ",%.9f" * 6, [(a, *b, *c) for a, b, c in zip(t.tolist(), gyro.tolist(), accel.tolist())]))
    write_text_atomic(mav / "imu0" / "sensor.yaml", imu_yaml(rec.meta))
    if rec.groundtruth is not None and groundtruth_folder is not None:
        (mav / groundtruth_folder).mkdir(exist_ok=True)
        full = groundtruth_folder == GROUNDTRUTH
        header = GT_HEADER if full else ",".join(GT_HEADER.split(",")[:8]).replace("#timestamp", "#timestamp [ns]")
        write_text_atomic(mav / groundtruth_folder / "data.csv",
                          _lines(header, "%d" + ",%.9f" * (16 if full else 7), groundtruth_rows(rec, full)))
        if full:
            write_text_atomic(mav / groundtruth_folder / "sensor.yaml", GT_YAML)
    write_extras(rec, out / EXTRAS)


def write_extras(rec: Recording, folder: Path) -> None:
    """The arsim extras: what makes the round trip exact (README: Recordings in standard layouts)."""
    write_text_atomic(folder / "meta.json", json.dumps(extras_meta(rec.meta), indent=2) + "\n")
    write_text_atomic(folder / "frames.csv", _csv_formatted(["t_ns", "exposure_ns", "iso"], "%d,%d,%s",
                                                            [(f["t_ns"], f["exposure_ns"], repr(f["iso"])) for f in rec.frames]))
    raw = sorted(((t, name, *v) for name in SENSORS[1:]
                  for t, v in zip(rec.imu[name].t_ns.tolist(), rec.imu[name].values.tolist())), key=lambda r: (r[0], r[1]))
    write_text_atomic(folder / "imu.csv", _csv_formatted(["t_ns", "sensor", "x", "y", "z"], "%d,%s" + ",%.9f" * 3, raw))
    t, q = rec.orientation
    write_text_atomic(folder / "orientation.csv", _csv_formatted(["t_ns", "qx", "qy", "qz", "qw"], "%d" + ",%.9f" * 4,
                                                                 zip(t.tolist(), *q.as_quat().T.tolist())))
    if rec.burst:
        (folder / "burst").mkdir(exist_ok=True)
    rows = []
    for k, b in enumerate(rec.burst):
        name = f"burst/{k:02d}.png"
        write_bytes_atomic(folder / name, png_of_frame(rec.folder / b["file"]))
        rows.append((b["exposure_ns"], repr(b["iso"]), name))
    write_text_atomic(folder / "burst.csv", _csv_formatted(["exposure_ns", "iso", "file"], "%d,%s,%s", rows))


# ----------------------------------------------------------------------------------------------------
# Reading


def data_rows(path: Path, columns: int, what: str) -> list[tuple[int, list[str]]]:
    """A EuRoC CSV's data rows (comment lines, '#...', and blank ones skipped) as (line number, fields), each
    with at least `columns` fields."""
    if not path.is_file():
        raise ArsimError(f"{path}: missing (or not a file); a EuRoC folder holds {what} there")
    try:
        text = path.read_text(encoding="utf-8")
    except (UnicodeDecodeError, OSError) as exc:
        raise ArsimError(f"{path}: cannot be read as UTF-8 text ({getattr(exc, 'strerror', None) or exc})") from None
    rows = []
    for k, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = [f.strip() for f in line.split(",")]
        if len(fields) < columns:
            raise ArsimError(f"{path}: line {k} has {len(fields)} fields, expected {columns} ({what})")
        rows.append((k, fields))
    return rows


def numbers(path: Path, rows: list[tuple[int, list[str]]], columns: int) -> tuple[np.ndarray, np.ndarray]:
    """Integer timestamps (first field) and float values (the next columns - 1) of data rows, checked: numbers,
    finite, the timestamps increasing (the file and line that breaks it named)."""
    t, values = np.zeros(len(rows), np.int64), np.zeros((len(rows), columns - 1))
    for i, (k, fields) in enumerate(rows):
        try:
            t[i] = int(fields[0])
            values[i] = [float(v) for v in fields[1:columns]]
        except (ValueError, OverflowError):
            raise ArsimError(f"{path}: line {k} holds a value that is not a number ({','.join(fields[:columns])[:80]})") from None
        if not np.isfinite(values[i]).all():
            raise ArsimError(f"{path}: line {k} has a NaN or infinite value")
        if i and t[i] <= t[i - 1]:
            raise ArsimError(f"{path}: line {k}: timestamp {t[i]} ns is not after the previous row's {t[i - 1]} ns; "
                             "the rows must be in increasing time order (sort them, drop repeats)")
    return t, values


def _yaml(path: Path, what: str) -> dict:
    if not path.is_file():
        raise ArsimError(f"{path}: missing; a EuRoC folder describes {what} there (sensor.yaml)")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError, OSError) as exc:
        raise ArsimError(f"{path}: is not readable YAML ({str(exc).splitlines()[0] if str(exc) else exc})") from None
    if not isinstance(data, dict):
        raise ArsimError(f"{path}: holds no YAML mapping; give EuRoC's sensor.yaml keys")
    return data


def _floats(value, n: int) -> list[float] | None:
    if not isinstance(value, list) or len(value) != n or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                                 and math.isfinite(v) for v in value):
        return None
    return [float(v) for v in value]


def read_camera_yaml(path: Path) -> tuple[dict, list]:
    """meta.json's camera and camera_to_device from EuRoC's cam0/sensor.yaml."""
    data = _yaml(path, "the camera")
    intrinsics = _floats(data.get("intrinsics"), 4)
    if intrinsics is None:
        raise ArsimError(f"{path}: no intrinsics [fu, fv, cu, cv] (found {str(data.get('intrinsics'))[:60]!r}); "
                         "the camera's intrinsics are needed: add them from its calibration")
    if data.get("camera_model", "pinhole") != "pinhole":
        raise ArsimError(f"{path}: camera_model {data.get('camera_model')!r}; arsim reads pinhole cameras")
    model = data.get("distortion_model", "radial-tangential")
    if model not in ("radial-tangential", "radtan", "plumb_bob"):
        raise ArsimError(f"{path}: distortion_model {model!r}; arsim reads radial-tangential (k1, k2; p1, p2 dropped)")
    distortion = data.get("distortion_coefficients", [0.0, 0.0, 0.0, 0.0])
    coefficients = _floats(distortion, len(distortion) if isinstance(distortion, list) and len(distortion) >= 2 else 4)
    resolution = data.get("resolution")
    if not (isinstance(resolution, list) and len(resolution) == 2 and all(type(v) is int for v in resolution)):
        raise ArsimError(f"{path}: resolution is {str(resolution)[:40]!r}, not [width, height] in pixels")
    if coefficients is None:
        raise ArsimError(f"{path}: distortion_coefficients is not a list of numbers [k1, k2, p1, p2]")
    rate = data.get("rate_hz")
    camera = {"width": resolution[0], "height": resolution[1], "fx": intrinsics[0], "fy": intrinsics[1],
              "cx": intrinsics[2], "cy": intrinsics[3], "k1": coefficients[0], "k2": coefficients[1],
              "fps": float(rate) if isinstance(rate, (int, float)) and not isinstance(rate, bool) else None}
    return camera, _t_bs_rotation(path, data)


def _t_bs_rotation(path: Path, data: dict) -> list:
    t_bs = data.get("T_BS", {"data": np.eye(4).ravel().tolist()})
    m = _floats(t_bs.get("data") if isinstance(t_bs, dict) else None, 16)
    if m is None:
        raise ArsimError(f"{path}: T_BS is not a 4 x 4 matrix (rows: 4, cols: 4, data: 16 numbers)")
    rotation = np.array(m).reshape(4, 4)[:3, :3].tolist()
    if problem := _rotation_problem(rotation):
        raise ArsimError(f"{path}: T_BS's rotation is {problem}")
    return rotation


def read_frames(root: Path, camera: dict, exposures: dict[int, tuple[int, float]]) -> list[dict]:
    path = root / MAV / "cam0" / "data.csv"
    rows = data_rows(path, 2, "the frames: timestamp [ns], file name")
    t, _ = numbers(path, [(k, [f[0]]) for k, f in rows], 1)
    frames = []
    for (k, fields), t_ns in zip(rows, t.tolist()):
        name = f"{MAV}/cam0/data/{fields[1]}"
        if not (root / name).is_file():
            raise ArsimError(f"{path}: line {k} names {fields[1]}, which is not in {root / MAV / 'cam0' / 'data'}")
        _check_frame_header(root / name, camera["width"], camera["height"])
        exposure_ns, iso = exposures.get(t_ns, (FOREIGN_EXPOSURE_NS, FOREIGN_ISO))
        frames.append({"t_ns": t_ns, "exposure_ns": exposure_ns, "iso": iso, "file": name})
    return frames


def read_extras(root: Path) -> tuple[dict | None, dict, dict | None, tuple | None, list[dict]]:
    """The arsim extras where the folder has them: meta, {t_ns: (exposure_ns, iso)}, raw accelerometer and
    magnetometer streams, the fused orientation, the burst."""
    folder = root / EXTRAS
    if not (folder / "meta.json").is_file():
        return None, {}, None, None, []
    from arsim.sensors.recording import _increasing, _numbers, _read_csv

    try:
        meta = json.loads((folder / "meta.json").read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError, OSError) as exc:
        raise ArsimError(f"{folder / 'meta.json'}: is not readable JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise ArsimError(f"{folder / 'meta.json'}: holds no JSON object")
    path = folder / "frames.csv"
    rows = _read_csv(path, ["t_ns", "exposure_ns", "iso"])
    values = _numbers(path, rows, slice(0, 3))
    exposures = {int(v[0]): (int(v[1]), float(v[2])) for v in values}
    path = folder / "imu.csv"
    rows = _read_csv(path, ["t_ns", "sensor", "x", "y", "z"])
    raw = {}
    for name in SENSORS[1:]:
        mine = [[r[0], *r[2:]] for r in rows if r[1] == name]
        v = _numbers(path, mine, slice(0, 4))
        t = v[:, 0].astype(np.int64) if mine else np.zeros(0, np.int64)
        _increasing(path, t, name)
        if mine:
            raw[name] = SensorStream(name, t, v[:, 1:])
    path = folder / "orientation.csv"
    v = _numbers(path, _read_csv(path, ["t_ns", "qx", "qy", "qz", "qw"]), slice(0, 5))
    _increasing(path, v[:, 0].astype(np.int64), "orientations")
    if len(v) < 2:
        raise ArsimError(f"{path}: holds {len(v)} orientations, need at least 2")
    orientation = (v[:, 0].astype(np.int64), exact_rotations(v[:, 1:], str(path)))
    path = folder / "burst.csv"
    rows = _read_csv(path, ["exposure_ns", "iso", "file"])
    burst = []
    for n, row in zip(_numbers(path, rows, slice(0, 2)), rows):
        if not (folder / row[2]).is_file():
            raise ArsimError(f"{path}: names {row[2]}, which is missing")
        burst.append({"exposure_ns": int(n[0]), "iso": float(n[1]), "file": f"{EXTRAS}/{row[2]}"})
    return meta, exposures, raw, orientation, burst


def read_groundtruth(path: Path) -> tuple | None:
    if not path.is_file():
        return None
    rows = data_rows(path, 8, "the ground truth: timestamp, position, quaternion w, x, y, z")
    t, v = numbers(path, [(k, f[:8]) for k, f in rows], 8)
    if len(t) < 2:
        raise ArsimError(f"{path}: holds {len(t)} poses, need at least 2")
    norms = np.linalg.norm(v[:, 3:7], axis=1)
    if (norms < 1e-6).any():
        raise ArsimError(f"{path}: line {rows[int(np.flatnonzero(norms < 1e-6)[0])][0]} has a zero quaternion")
    return t, v[:, :3], exact_rotations(np.column_stack([v[:, 4:7], v[:, 3]]), str(path))  # w, x, y, z -> x, y, z, w


def read_euroc(root: Path, exposures_from=None, photometric: Photometric | None = None,
               source_format: str = "euroc") -> Recording:
    """A EuRoC folder (or TUM-VI's: exposures_from gives its exposure times, photometric its calibration) as a
    Recording; every problem one ArsimError naming the file and line."""
    root = Path(root)
    camera, camera_to_device = read_camera_yaml(root / MAV / "cam0" / "sensor.yaml")
    if problem := _camera_problem({**camera, "fps": camera["fps"] or 1.0}):
        raise ArsimError(f"{root / MAV / 'cam0' / 'sensor.yaml'}: {problem}")
    extras, exposures, raw, orientation, burst = read_extras(root)
    if exposures_from is not None:
        exposures = {t: (e, exposures.get(t, (e, FOREIGN_ISO))[1]) for t, e in exposures_from.items()}
    frames = read_frames(root, camera, exposures)
    if camera["fps"] is None:  # (rate_hz is optional) from the frames' median interval
        dt = np.median(np.diff([f["t_ns"] for f in frames])) if len(frames) > 1 else 0
        camera["fps"] = 1e9 / dt if dt > 0 else 30.0
    path = root / MAV / "imu0" / "data.csv"
    t, v = numbers(path, data_rows(path, 7, "the IMU: timestamp [ns], gyroscope x y z [rad/s], accelerometer x y z [m/s^2]"), 7)
    imu = imu_streams(t, v[:, :3], v[:, 3:6], raw)
    groundtruth = (read_groundtruth(root / MAV / GROUNDTRUTH / "data.csv")
                   or read_groundtruth(root / MAV / "mocap0" / "data.csv"))
    meta = layout_meta(camera, camera_to_device, extras, frames, imu, source_format)
    if orientation is None:
        orientation = fused_orientation(imu, groundtruth, meta["fusion"], str(path))
    if photometric is not None:
        photometric.check(camera["width"], camera["height"], str(root / "dso" / "cam0"))
    return recording_of(root, meta, frames, burst, imu, orientation, groundtruth, photometric)
