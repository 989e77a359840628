"""Light estimates per frame of a capture sweep, as estimates.jsonl (README: Light estimation): one JSON
object a frame with `frame`, `t_ns` and, per estimator, its estimate's shapes (shapes.py):

- `truth`: from the true environment (at infinity: the same at every position);
- `capture`: from the probe as the capture had built it by that frame (its snapshot of the last whole
  second: CaptureResult.snapshots; black where nothing was seen yet), so that the estimate converges over
  the sweep;
- `single`: from that frame's image alone (single_frame.py), the baseline;
- `file`: read from a JSONL the user gives (their estimator's output), checked line by line.

Per estimator: `sh_radiance` (27 numbers, RGB interleaved per coefficient), `main_light`
(`direction_world`, `direction_camera` where the camera's orientation is known, `intensity_rgb`),
`ambient_intensity`, `color_correction` (4 numbers).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from arsim.core.errors import ArsimError
from arsim.estimate.shapes import LightEstimate, estimate_light, sh_cubemap

FIELDS = {"sh_radiance": 27, "color_correction": 4}  # flat lists and their lengths


def estimate_json(e: LightEstimate) -> dict:
    """An estimate's shapes as the JSON object of one estimator in one line."""
    return {"sh_radiance": [float(v) for v in e.sh_radiance.reshape(-1)],
            "main_light": {"direction_world": [float(v) for v in e.main_light_direction],
                           "intensity_rgb": [float(v) for v in e.main_light_intensity]},
            "ambient_intensity": float(e.ambient_intensity),
            "color_correction": [float(v) for v in e.color_correction]}


def line_estimate(line: dict) -> LightEstimate:
    """A LightEstimate of one estimator's object in a line (a user's file line, read_estimates'); a line
    gives no cubemap, so its cubemap is its SH's radiance (clamped at 0) at the texel centres."""
    sh = np.asarray(line["sh_radiance"], dtype=np.float64).reshape(9, 3)
    light = line["main_light"]
    direction = np.asarray(light["direction_world"], dtype=np.float64)
    return LightEstimate(sh, direction / np.linalg.norm(direction), np.asarray(light["intensity_rgb"], dtype=np.float64),
                         sh_cubemap(sh).astype(np.float32), float(line["ambient_intensity"]),
                         np.asarray(line["color_correction"], dtype=np.float64))


def snapshot_index(snapshot_times_s: np.ndarray, t_s: float) -> int | None:
    """The last snapshot taken at or before t_s (None: none yet)."""
    k = int(np.searchsorted(snapshot_times_s, t_s, side="right")) - 1
    return k if k >= 0 else None


def _in_camera(estimate: dict, camera_to_world: np.ndarray) -> dict:
    """The estimate with its main light's direction also in the camera's frame (OpenCV axes)."""
    light = dict(estimate["main_light"])
    light["direction_camera"] = [float(v) for v in np.asarray(camera_to_world).T @ np.asarray(light["direction_world"], dtype=np.float64)]
    return dict(estimate, main_light=light)


def estimate_lines(frame_times_ns: np.ndarray, truth: np.ndarray | None, snapshots: list,
                   given: list[dict] | None = None, single: list[LightEstimate] | None = None,
                   camera_to_world: np.ndarray | None = None) -> list[dict]:
    """One dict a frame: `frame`, `t_ns`, `truth` (where the true environment is known: truth not None), `capture` (absent before the first snapshot), `frame`'s
    estimate from that frame alone (where given: single_frame.py) and `file` (where given: the user's line
    for that frame). camera_to_world (K, 3, 3): the phone's camera orientation per frame, which adds each
    main light's direction in the camera's frame (`direction_camera`)."""
    truth_json = estimate_json(estimate_light(truth)) if truth is not None else None
    times = np.array([t for t, _ in snapshots])
    estimates = [estimate_json(estimate_light(light)) for _, light in snapshots]
    start = frame_times_ns[0]
    by_frame = {line["frame"]: line for line in given or []}
    lines = []
    for k, t_ns in enumerate(frame_times_ns):
        line = {"frame": k, "t_ns": int(t_ns)} | ({"truth": truth_json} if truth_json is not None else {})
        s = snapshot_index(times, (t_ns - start) * 1e-9) if len(times) else None
        if s is not None:
            line["capture"] = estimates[s]
        if single is not None:
            line["single"] = estimate_json(single[k])
        if k in by_frame:
            line["file"] = {key: by_frame[k][key] for key in ("sh_radiance", "main_light", "ambient_intensity", "color_correction")}
        if camera_to_world is not None:
            for name in ("truth", "capture", "single", "file"):
                if name in line:
                    line[name] = _in_camera(line[name], camera_to_world[k])
        lines.append(line)
    return lines


def _finite_list(value, length: int | None) -> bool:
    return (isinstance(value, list) and (length is None or len(value) == length)
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))


def read_estimates(path: Path, frames: int) -> list[dict]:
    """A user's estimates (JSONL: per line `frame`, and the four estimate keys) checked line by line: a
    missing key, a number that is not finite, a list of the wrong length, a frame out of order or beyond
    the recording's raise ArsimError naming the line."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ArsimError(f"{path}: cannot read the estimates ({exc.__class__.__name__}); give a UTF-8 JSONL file") from None
    lines, last = [], -1
    for number, raw in enumerate(text.splitlines(), 1):
        if not raw.strip():
            continue
        where = f"{path}, line {number}"
        try:
            line = json.loads(raw, parse_constant=lambda name: float("nan"))
        except ValueError as exc:
            raise ArsimError(f"{where}: not JSON ({str(exc).splitlines()[0][:80]}); one JSON object a line") from None
        if not isinstance(line, dict):
            raise ArsimError(f"{where}: a line holds one JSON object (frame, sh_radiance, main_light, ...)")
        for key in ("frame", "sh_radiance", "main_light", "ambient_intensity", "color_correction"):
            if key not in line:
                raise ArsimError(f"{where}: no \"{key}\"; every line needs frame, sh_radiance, main_light, "
                                 f"ambient_intensity and color_correction")
        frame = line["frame"]
        if type(frame) is not int or not 0 <= frame < frames:
            raise ArsimError(f"{where}: frame {frame!r} is not a frame of the recording (0 to {frames - 1})")
        if frame <= last:
            raise ArsimError(f"{where}: frame {frame} comes after frame {last}; give the frames in increasing order")
        last = frame
        for key, length in FIELDS.items():
            if not _finite_list(line[key], length):
                got = len(line[key]) if isinstance(line[key], list) else type(line[key]).__name__
                raise ArsimError(f"{where}: {key} needs {length} finite numbers (got {got}, or one not finite)")
        light = line["main_light"]
        if not (isinstance(light, dict) and _finite_list(light.get("direction_world"), 3)
                and _finite_list(light.get("intensity_rgb"), 3)):
            raise ArsimError(f"{where}: main_light needs direction_world and intensity_rgb, 3 finite numbers each")
        if not np.linalg.norm(light["direction_world"]) > 0:
            raise ArsimError(f"{where}: main_light direction_world is zero; give a direction")
        ambient = line["ambient_intensity"]
        if not (isinstance(ambient, (int, float)) and not isinstance(ambient, bool) and math.isfinite(ambient)):
            raise ArsimError(f"{where}: ambient_intensity needs a finite number")
        lines.append(line)
    if not lines:
        raise ArsimError(f"{path}: no estimates in the file; one JSON object a line")
    return lines
