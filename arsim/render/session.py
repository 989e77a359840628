"""The AR session (thesis 5.1) over an AR recording, on the render loop (loop.py): `run_session` lights
the objects with maps from the captured probe and renders beside each frame the truth frame, the same
objects lit by maps from the true environment, scored against it inside the mask by the scorer it is given
(the evaluation's FLIP); `run_profile` runs the loop lap after lap while step 3 bakes maps tile by tile, for
the profiler. What the poses and the timings measure is the evaluation's (arsim.evaluate.session).
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.png import read_frame, read_frames
from arsim.core.errors import ArsimError
from arsim.core.tags import DEFAULT_DETECTOR
from arsim.core.files import atomic_path, write_bytes_atomic
from arsim.core.gl import create_gl_context
from arsim.core.png import png_bytes
from arsim.lighting.mapset import MapSet
from arsim.lighting.methods import bake
from arsim.render.baking import BakeSettings, LoopBaker
from arsim.render.content import light_objects
from arsim.render.loop import GL_STEPS, FrameLoop, Shading
from arsim.render.renderer import Renderer, SceneObject
from arsim.sensors.frames import recording_camera
from arsim.sensors.recording import Recording
from arsim.tracking.apriltag import TagPose
from arsim.tracking.fusion import recording_tracker

STEPS = ("track", "relight", "background", "objects", "tone_mapping", "overlay", "readback", "truth_frame")


@dataclass(frozen=True)
class SessionSettings:
    method: str = "fast"  # map method of the materials that name none (the truth frame's maps the same)
    key: float = 0.18  # Reinhard's a
    white: float = 2.0  # L_white
    log_average: bool = False  # Reinhard's log-average instead of the mean luminance (thesis: the mean)
    saved_frames: Sequence[int] = ()  # frame indices written as PNG (default: four spread over the path)
    every: int = 1  # render every k-th frame of the AR path (a quick look; the video holds those frames)
    overlay: bool = False  # step 7: frame time and map state drawn at the top left (left out of the FLIP)
    flip_every: int = 1  # the truth frame and its FLIP on every k-th rendered frame (and on the saved ones)
    # The probe as the capture grew (angle maps, CaptureResult.snapshots), replayed over the session: PRT objects
    # relit from each in turn (the truth frames keep the true light); empty: relit once, from the final probe.
    lights: tuple = ()
    detector: str = DEFAULT_DETECTOR  # the tag detector ([ar] detector)
    fusion: bool = True  # the tag's poses fused with the IMU ([ar] fusion)


# (truth frame, frame, mask) -> score inside the mask, or a Future of it (a scorer working beside the loop)
Scorer = Callable[[np.ndarray, np.ndarray, np.ndarray], float | Future]


def _value(score: float | Future) -> float:
    return score.result() if isinstance(score, Future) else score


class _VideoWriter:
    """session.mp4 encoded on a thread beside the loop (OpenCV lets go of the GIL while it converts and
    encodes); frames are written in the order given."""

    def __init__(self, path: Path, fps: float, size: tuple[int, int]):
        self.video = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
        self.queue = queue.Queue(maxsize=8)  # (a few frames ahead at most: the loop waits rather than hoards)
        self.error = None
        self.thread = threading.Thread(target=self._encode, daemon=True)
        self.thread.start()

    def _encode(self) -> None:
        while (frame := self.queue.get()) is not None:
            if self.error is None:  # (after a failure the queue is still drained: the loop never waits on it)
                try:
                    self.video.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
                except Exception as e:  # raised in the loop's thread by close
                    self.error = e

    def write(self, frame: np.ndarray) -> None:
        self.queue.put(frame)

    def __enter__(self) -> "_VideoWriter":
        return self

    def __exit__(self, kind, error, trace) -> None:
        self.queue.put(None)
        self.thread.join()
        self.video.release()
        if self.error is not None and kind is None:
            raise self.error


@dataclass
class SessionResult:
    frames: np.ndarray  # (K,) indices of the AR path's frames rendered
    poses: list[TagPose]  # (K,) the tracker's, per frame rendered
    flip: np.ndarray  # (K,) the scorer's inside the mask; nan where no object was drawn or not measured (flip_every)
    step_ms: dict[str, list[float]] = field(default_factory=dict)  # CPU ms per step per frame
    gl_ms: dict[str, list[float]] = field(default_factory=dict)  # GL ms per GL step per frame
    records: list = field(default_factory=list)  # the render loop's FrameRecord per frame (the profile's input)
    # At the saved frames where the tag was found: the truth frame, the objects' mask and the frame lit by each
    # light estimate; and per estimator its score against the truth frame there.
    estimate_frames: dict = field(default_factory=dict)  # frame index -> {"truth_frame", "mask", "lit": {estimator: frame}}
    estimate_scores: dict = field(default_factory=dict)  # estimator -> {frame index: score}
    scored: bool = True  # whether truth frames were rendered and scored (False: the true environment is unknown)

    def tracked(self) -> dict[int, tuple[TagPose, float]]:
        """Per frame rendered: its pose and the CPU ms its tracking took (run_session's `tracked`)."""
        return {int(k): (pose, record.cpu_ms["track"]) for k, pose, record in zip(self.frames, self.poses, self.records)}


def maps_needed(objects: Sequence[SceneObject], method: str) -> dict[str, list[float]]:
    """Per map method, the exponents the objects' materials need (1: the irradiance map); materials that
    name no method take `method`."""
    needed: dict[str, set[float]] = {}
    for obj in objects:
        needed.setdefault(obj.material.method or method, {1.0}).add(float(obj.material.exponent))
    return {name: sorted(exponents) for name, exponents in needed.items()}


def session_maps(env: np.ndarray, needed: dict[str, list[float]], source: str = "") -> dict[str, MapSet]:
    """The maps of every method the objects need, computed from the angle map env (source: what it is)."""
    return {name: MapSet.of(name, exponents, bake(env, exponents, name).maps, source) for name, exponents in needed.items()}


def check_maps(maps: dict[str, MapSet], needed: dict[str, list[float]]) -> None:
    """ArsimError naming what is missing where given maps lack a method or an exponent the objects need."""
    for name, exponents in needed.items():
        missing = [s for s in exponents if s not in maps.get(name, {})]
        if missing:
            held = "; ".join(f"{m}: {', '.join(f'{s:g}' for s in ms.exponents)}" for m, ms in maps.items()) or "none"
            spec = ",".join(f"{s:g}" for s in exponents)
            raise ArsimError(f"no {name} maps for exponent {', '.join(f'{s:g}' for s in missing)} among the maps given "
                             f"({held}); bake them: arsim bake PROBE.exr -o DIR --method {name} --spec {spec}")


def _camera_and_tracker(rec: Recording, linear_of_code: np.ndarray, settings: SessionSettings) -> tuple:
    """The recording's camera, and a tracker for its table's tag that linearises frames with linear_of_code
    (fused with the recording's IMU where the settings say)."""
    camera = recording_camera(rec)
    return camera, recording_tracker(rec, linear_of_code, settings.detector, settings.fusion)


def _renderer(camera, maps: dict[str, MapSet], ctx, method: str, objects: list[SceneObject]) -> Renderer:
    renderer = Renderer(camera, maps.values(), ctx, method=method)
    for obj in objects:
        renderer.add(obj)
    return renderer


def run_session(rec: Recording, linear_of_code: np.ndarray, maps: dict[str, MapSet], truth_maps: dict[str, MapSet] | None,
                out_dir: Path,
                objects: list[SceneObject], score: Scorer, settings: SessionSettings = SessionSettings(),
                truth_objects: list[SceneObject] | None = None,
                progress: Callable[[float], None] = lambda fraction: None,
                estimates: dict[str, tuple[dict[str, MapSet], list[SceneObject]]] | None = None,
                tracked: dict[int, tuple[TagPose, float]] | None = None,
                error_map: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray | Future] | None = None,
                after_loop: Callable[[list], None] | None = None, settle: Callable[[], None] | None = None) -> SessionResult:
    """Run the AR session over an AR recording (rec: its ar/ part) with the virtual objects lit by `maps`
    (a set per method: from the captured probe, or baked before) and truth frames lit by
    `truth_maps` (the same from the true environment), each frame scored against its truth frame by
    `score` (truth_maps None: the true environment is unknown, no truth frame is rendered and nothing is scored:
    flip all NaN, estimate_frames without a truth frame); writes frames/*.png and session.mp4 into out_dir. truth_objects: the objects as the truth
    frames show them, where their directional light maps were baked from the true environment
    (light_objects); default: `objects`. estimates: per light estimator, its maps and objects (estimate.lit);
    at the saved frames the objects are also rendered lit by each, scored against the truth frame likewise.
    tracked: the frames' poses and tracking times from an earlier session over the same recording with the same
    tracker (SessionResult.tracked gives them), which are not tracked again. error_map: (truth frame, frame, mask) ->
    the error map (H, W) whose mean over the mask is the score (or its Future); where given, the estimates' frames
    hold their error maps ("errors": the estimates' frames show them) and their scores are those means.
    after_loop: called with the loop's FrameRecords once the last frame is drawn, before the scores are awaited
    (work that needs no score, done while a scorer beside the loop finishes). settle: then called to take a
    share of the scores not yet begun (FlipWorker.settle)."""
    ctx = create_gl_context()
    camera, tracker = _camera_and_tracker(rec, linear_of_code, settings)
    captured = _renderer(camera, maps, ctx, settings.method, objects)
    true_light = (None if truth_maps is None else  # (None: the true environment is unknown; nothing is scored)
                  _renderer(camera, truth_maps, ctx, settings.method, objects if truth_objects is None else truth_objects))
    estimated = {name: _renderer(camera, m, ctx, settings.method, o) for name, (m, o) in (estimates or {}).items()}
    estimate_frames, estimate_scores = {}, {name: {} for name in estimated}
    indices = np.arange(0, len(rec.frames), settings.every)
    count = len(indices)
    saved = set(settings.saved_frames or indices[np.linspace(0, count - 1, 4).round().astype(int)].tolist())
    (out_dir / "frames").mkdir(parents=True, exist_ok=True)
    step_ms = {name: [] for name in STEPS}
    gl_ms = {name: [] for name in GL_STEPS}
    poses, flips, records = [], np.full(count, np.nan), []
    fps = rec.meta["camera"].get("fps", 30.0) / settings.every
    shading = Shading(settings.key, settings.white, settings.log_average)
    loop = FrameLoop(ctx, tracker, captured, shading, settings.overlay, settings.method, lights=settings.lights,
                     light_frames=count, tracked=tracked)
    pending = {}  # frame n -> its score (a Future where the scorer works beside the loop)
    error_maps = {}  # (frame index, estimator) -> error_map's (or its Future)
    with (atomic_path(out_dir / "session.mp4") as video_path,
          _VideoWriter(video_path, fps, (camera.width, camera.height)) as video):
        # (decoded ahead of the loop, as RGBA: the layout step 4 uploads)
        frames = read_frames((rec.folder / rec.frames[k]["file"] for k in indices), alpha=True)
        for n, (k, frame) in enumerate(zip(indices, frames)):
            time_s = frame_time_s(rec, k)
            pose, record = loop.run(frame, int(k), time_s)
            poses.append(pose)
            records.append(record)
            for name, ms in record.cpu_ms.items():
                step_ms[name].append(ms)
            for name, ms in record.gl_ms.items():
                gl_ms[name].append(ms)
            overlay_box = captured.overlay_box if settings.overlay else None
            start = time.perf_counter()
            out = captured.read_output()
            mask = captured.read_mask() > 0.5
            step_ms["readback"].append(1000 * (time.perf_counter() - start))
            if true_light is None and estimated and pose.found and k in saved and mask.any():
                # no truth frame to score against: the objects lit by each estimate are still shown
                if overlay_box is not None:
                    mask[overlay_box] = False
                lit = {name: _lit_frame(r, pose, time_s, frame, settings, overlay_box, out) for name, r in estimated.items()}
                estimate_frames[int(k)] = {"truth_frame": None, "mask": mask, "lit": lit}
            if true_light is not None and pose.found and (n % settings.flip_every == 0 or k in saved):
                start = time.perf_counter()
                # (the same overlay pixels on both, as FLIP's filters reach past its box, and those pixels left
                # out of the mask: they are not the objects' light)
                truth_frame = _lit_frame(true_light, pose, time_s, frame, settings, overlay_box, out)
                if overlay_box is not None:
                    mask[overlay_box] = False
                if mask.any():
                    pending[n] = score(truth_frame, out, mask)
                step_ms["truth_frame"].append(1000 * (time.perf_counter() - start))
                if k in saved:  # (shown beside the frame in the report)
                    (out_dir / "frames" / "truth").mkdir(exist_ok=True)
                    write_bytes_atomic(out_dir / "frames" / "truth" / f"{k:06d}.png", png_bytes(truth_frame))
                if estimated and k in saved and mask.any():
                    lit = {name: _lit_frame(r, pose, time_s, frame, settings, overlay_box, out) for name, r in estimated.items()}
                    estimate_frames[int(k)] = {"truth_frame": truth_frame, "mask": mask, "lit": lit}
                    for name, image in lit.items():
                        if error_map is not None:  # (the map shown; its mean over the mask is the score)
                            error_maps[int(k), name] = error_map(truth_frame, image, mask)
                        else:
                            estimate_scores[name][int(k)] = score(truth_frame, image, mask)
            video.write(out)
            if k in saved:
                write_bytes_atomic(out_dir / "frames" / f"{k:06d}.png", png_bytes(out))
            if n % 10 == 0 or n == count - 1:
                progress((n + 1) / count)
    if after_loop is not None:
        after_loop(records)
    if settle is not None:
        settle()
    for n, value in pending.items():
        flips[n] = _value(value)
    estimate_scores = {name: {k: _value(v) for k, v in scores.items()} for name, scores in estimate_scores.items()}
    for (k, name), error in error_maps.items():
        error = estimate_frames[k].setdefault("errors", {})[name] = _value(error)
        estimate_scores[name][k] = float(error[estimate_frames[k]["mask"]].mean())
    return SessionResult(indices, poses, flips, step_ms, gl_ms, records, estimate_frames, estimate_scores,
                         true_light is not None)


def _lit_frame(renderer: Renderer, pose: TagPose, time_s: float, frame: np.ndarray, settings: SessionSettings,
               overlay_box, shown: np.ndarray) -> np.ndarray:
    """The camera frame with the objects drawn at the pose by a renderer of other light (the truth's, an
    estimate's), tone mapped as the session's; the overlay's pixels copied from the frame shown."""
    renderer.render_objects(Rotation.from_matrix(pose.rotation), pose.translation, time_s)
    renderer.background_pass(frame)
    renderer.tonemap_pass(settings.key, settings.white, settings.log_average)
    out = renderer.read_output()
    if overlay_box is not None:
        out = out.copy()
        out[overlay_box] = shown[overlay_box]
    return out


def frame_time_s(rec: Recording, k: int) -> float:
    """The recorded frame k's time from the recording's first frame, seconds (where the objects that
    move are in it)."""
    return (rec.frames[k]["t_ns"] - rec.frames[0]["t_ns"]) * 1e-9


def lap_frame(n: int, count: int) -> int:
    """The recorded frame shown as the loop's n-th: along the path and back, again and again (a camera
    moves on; from the path's end to its start would be a jump no device makes, and the objects' cost with
    it)."""
    if count == 1:
        return 0
    k = n % (2 * count - 2)
    return k if k < count else 2 * count - 2 - k


def run_profile(rec: Recording, linear_of_code: np.ndarray, probe: np.ndarray, objects: list[SceneObject],
                bake_settings: BakeSettings, budget_ms: float, max_frames: int, out_dir: Path | None = None,
                settings: SessionSettings = SessionSettings(method="mipmap", overlay=True), tail_frames: int = 30,
                poses: dict | None = None, progress: Callable[[float], None] = lambda fraction: None) -> list:
    """The render loop over the AR path's frames, along it and back again and again, while step 3 bakes
    the objects' maps from `probe` with `bake_settings` (the objects lit by `settings.method` maps meanwhile), until the
    bake is complete and tail_frames more, or max_frames. The tracker runs once per recorded frame (its
    pose is kept in `poses` for the next lap, and the next run). With out_dir, frames at a quarter and a
    half of the bake and after it go to out_dir/frames (the progress display). Returns the loop's
    FrameRecord per frame (the profile's input)."""
    ctx = create_gl_context()
    camera, tracker = _camera_and_tracker(rec, linear_of_code, settings)
    needed = maps_needed(objects, settings.method)
    renderer = _renderer(camera, session_maps(probe, needed), ctx, settings.method, light_objects(objects, probe))
    baker = LoopBaker(probe, needed[settings.method], bake_settings, ctx)
    loop = FrameLoop(ctx, tracker, renderer, Shading(settings.key, settings.white, settings.log_average), settings.overlay,
                     settings.method, baker, budget_ms, pose_cache={} if poses is None else poses, lights=settings.lights,
                     light_frames=len(rec.frames))
    marks = [0.25, 0.5, 1.0]
    if out_dir is not None:
        (out_dir / "frames").mkdir(parents=True, exist_ok=True)
    # The frames of the first lap are kept decoded for the next: a camera hands the app its frames
    # decoded, and a PNG's decoding (9 ms here) would otherwise double the profile's wall time.
    decoded: dict[int, np.ndarray] = {}

    def camera_frame(k: int) -> np.ndarray:
        if k not in decoded:
            decoded[k] = read_frame(rec.folder / rec.frames[k]["file"], alpha=True)
        return decoded[k]

    loop.warm_up(camera_frame(0), 0, frame_time_s(rec, 0))
    records, after = [], 0
    for n in range(max_frames):
        k = lap_frame(n, len(rec.frames))
        frame = camera_frame(k)
        _, record = loop.run(frame, k, frame_time_s(rec, k))
        records.append(record)
        if out_dir is not None and marks and (loop.baked_in_use if marks[0] >= 1.0 else baker.progress >= marks[0]):
            name = f"bake_{int(100 * marks.pop(0)):03d}pct_frame{n:06d}.png"
            write_bytes_atomic(out_dir / "frames" / name, png_bytes(renderer.read_output()))
        after += loop.baked_in_use
        if after > tail_frames:
            break
        if n % 20 == 0:  # (it ends when the bake is done, or at max_frames: the nearer of the two)
            progress(max(baker.progress, (n + 1) / max_frames))
    progress(1.0)
    baker.release()
    return records
