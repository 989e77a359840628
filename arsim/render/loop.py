"""The render loop of thesis 5.1, one camera frame at a time: the tag's pose (steps 1-2), a few tiles of
the maps being baked (3), the camera frame as the background (4), the virtual objects into the HDR colour
and the mask (5), the masked tone mapping (6) and the overlay (7). Every step is timed on the CPU around
glFinish and, for the GL ones, with a timer query; the records are what the profiler reads.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.gl import query_ms
from arsim.render.baking import LoopBaker
from arsim.render.renderer import Renderer
from arsim.tracking.apriltag import TagPose, TagTracker

GL_STEPS = ("bake", "background", "objects", "tone_mapping", "overlay")
# The render thread's steps (3-7; steps 1-2, the tracker, run on the camera's): "relight" is PRT's, the
# objects' coefficients recomputed from the light when it changes (CPU and an upload, no draw).
FRAME_STEPS = ("bake", "relight", "background", "objects", "tone_mapping", "overlay")
# The share of the budget the bake leaves free: the other steps' time varies from frame to frame (objects
# coming closer) and so does the bake's. Over 3000 frames of bake_512: 0.05 kept 98.9 % of frames within
# budget, 0.12 kept 99.5 %.
BUDGET_MARGIN = 0.12
REST_FRAMES = 8  # the recent frames whose other steps' time the bake leaves room for


@dataclass(frozen=True)
class Shading:
    key: float = 0.18  # Reinhard's a
    white: float = 2.0  # L_white
    log_average: bool = False


@dataclass
class FrameRecord:
    index: int  # the camera frame's index in the recording
    start_ms: float  # since the loop's first frame began
    cpu_ms: dict[str, float] = field(default_factory=dict)  # per step that ran
    gl_ms: dict[str, float] = field(default_factory=dict)  # per GL step with a valid timer reading (core.gl.timer_ms)
    gl_dropped: dict[str, str] = field(default_factory=dict)  # per GL step whose reading was no time: why (TIMER_DROPPED)
    step_start_ms: dict[str, float] = field(default_factory=dict)
    found: bool = False
    bake_tiles: int = 0
    bake_progress: float = 1.0  # after this frame: the share of texels baked
    bake_work_progress: float = 1.0  # and of the bake's work done
    bake_done: bool = False  # the bake's last tile was done in this frame

    @property
    def total_ms(self) -> float:
        return sum(self.cpu_ms.values())


class FrameLoop:
    """Runs the render loop's steps on frames; `baker` (optional) bakes within `budget_ms` per frame and
    hands its maps to the renderer when done."""

    def __init__(self, ctx, tracker: TagTracker, renderer: Renderer, shading: Shading = Shading(), overlay: bool = False,
                 maps_label: str = "", baker: LoopBaker | None = None, budget_ms: float = 33.3,
                 pose_cache: dict[int, TagPose] | None = None, lights: Sequence[np.ndarray] = (), light_frames: int = 1,
                 tracked: dict[int, tuple[TagPose, float]] | None = None):
        self.ctx, self.tracker, self.renderer, self.shading = ctx, tracker, renderer, shading
        self.pose_cache = pose_cache  # a recording's frames seen again (a loop over its path): their poses
        # The same frames tracked before by the same tracker (a run's reused tracking): per frame its pose and
        # the CPU ms that tracking took, recorded as step "track" (the tracker is deterministic).
        self.tracked = tracked
        self.overlay, self.maps_label, self.baker, self.budget_ms = overlay, maps_label, baker, budget_ms
        self.query = ctx.query(time=True)
        self.origin = None
        self.last_frame_ms = 0.0
        # Steps 4-7 of recent frames (CPU ms), apart for frames with and without the tag: those without draw
        # no object, and the two alternate when the tag is lost and found again.
        self.recent_rest = {found: deque(maxlen=REST_FRAMES) for found in (False, True)}
        self.baked_in_use = False
        # The growing probe replayed over light_frames frames (angle maps, the capture's snapshots): the PRT
        # objects relit from each in turn (step "relight"), as an app relighting while it captures.
        self.lights, self.light_frames, self.frames_run, self.light_index = list(lights), max(light_frames, 1), 0, -1

    def _timed(self, record: FrameRecord, name: str, work: Callable[[], None], gl: bool = True) -> None:
        self.ctx.finish()
        start = time.perf_counter()
        record.step_start_ms[name] = 1000 * (start - self.origin)
        if gl:
            with self.query:
                work()
            self.ctx.finish()
            self._gl_reading(record, name, *query_ms(self.query))
        else:
            work()
        record.cpu_ms[name] = 1000 * (time.perf_counter() - start)

    @staticmethod
    def _gl_reading(record: FrameRecord, name: str, ms: float | None, dropped: str | None) -> None:
        if ms is None:
            record.gl_dropped[name] = dropped
        else:
            record.gl_ms[name] = ms

    def _bake(self, record: FrameRecord) -> None:
        # The most the other steps took in recent frames like this one: their time rises for frames on end
        # as the objects come closer (a 90th percentile over 30 frames lagged behind, and missed twice as
        # many frames).
        recent = self.recent_rest[record.found]
        rest = max(recent) if recent else 0.0
        # The tracker works on the camera's thread (as Vuforia in the thesis's app): only steps 3-7 share
        # the render thread's budget.
        available = self.budget_ms * (1 - BUDGET_MARGIN) - rest
        record.bake_tiles = self.baker.step(available)
        record.bake_done = self.baker.done
        if self.baker.done and not self.baked_in_use:  # the app switches to the baked maps
            for exponent, anglemap in zip(self.baker.exponents, self.baker.maps()):
                self.renderer.update_map("", exponent, anglemap)
            self.baked_in_use = True

    def _pose(self, frame: np.ndarray, index: int, record: FrameRecord | None = None) -> TagPose:
        """The tracker's pose for a frame (timed as step "track" into record), or the one kept for it."""
        if self.pose_cache is not None and index in self.pose_cache:
            return self.pose_cache[index]
        if self.tracked is not None and index in self.tracked:
            pose, ms = self.tracked[index]
            if record is not None:
                record.step_start_ms["track"] = 1000 * (time.perf_counter() - self.origin)
                record.cpu_ms["track"] = ms
            return pose
        poses = []
        if record is None:
            poses.append(self.tracker.track(frame, index))
        else:
            self._timed(record, "track", lambda: poses.append(self.tracker.track(frame, index)), gl=False)
        if self.pose_cache is not None:
            self.pose_cache[index] = poses[0]
        return poses[0]

    def warm_up(self, frame: np.ndarray, index: int, time_s: float = 0.0) -> None:
        """Run every pass once, unrecorded, as an app does while it loads: llvmpipe compiles a shader's
        machine code at its first draw (up to 100 ms), which would otherwise land in the first frames."""
        pose = self._pose(frame, index)
        if self.baker is not None:
            self.baker.warm_up()
        self.renderer.background_pass(frame)
        if pose.found:
            self.renderer.render_objects(Rotation.from_matrix(pose.rotation), pose.translation, time_s)
            self.renderer.tonemap_pass(self.shading.key, self.shading.white, self.shading.log_average)
        if self.overlay:
            self.renderer.overlay_pass(["warming up"], self.baker.thumbnail if self.baker is not None else None)
        self.ctx.finish()

    def run(self, frame: np.ndarray, index: int, time_s: float = 0.0) -> tuple[TagPose, FrameRecord]:
        """One frame: the recorded frame `index` (its pose is kept per index), taken at time_s (where the
        objects that move are)."""
        now = time.perf_counter()
        if self.origin is None:
            self.origin = now
        record = FrameRecord(index, 1000 * (now - self.origin))
        pose = self._pose(frame, index, record)
        record.found = pose.found
        if self.baker is not None and not self.baked_in_use:
            # (timed on the CPU here; the baker times its own GL work: timer queries cannot nest)
            self._timed(record, "bake", lambda: self._bake(record), gl=False)
            if self.baker.last_gl_ms is not None or self.baker.last_gl_dropped is not None:  # (a frame it drew in)
                self._gl_reading(record, "bake", self.baker.last_gl_ms, self.baker.last_gl_dropped)
            record.bake_progress = self.baker.progress
            record.bake_work_progress = self.baker.work_progress
        r = self.renderer
        if self.lights:
            index = min(self.frames_run * len(self.lights) // self.light_frames, len(self.lights) - 1)
            if index != self.light_index:
                self._timed(record, "relight", lambda: r.relight_probe(self.lights[index]), gl=False)
                self.light_index = index
        self.frames_run += 1
        self._timed(record, "background", lambda: r.background_pass(frame))
        if pose.found:  # lost frames draw no object (as the thesis's app)
            rotation = Rotation.from_matrix(pose.rotation)
            self._timed(record, "objects", lambda: r.render_objects(rotation, pose.translation, time_s))
            self._timed(record, "tone_mapping", lambda: r.tonemap_pass(self.shading.key, self.shading.white, self.shading.log_average))
        else:
            r.no_objects()
        if self.overlay:
            lines = [f"frame {index}  {self.last_frame_ms:5.1f} ms", self.status_line(pose.found)]
            baking = self.baker is not None and not self.baked_in_use
            self._timed(record, "overlay", lambda: r.overlay_pass(lines, self.baker.thumbnail if baking else None))
        self.recent_rest[pose.found].append(sum(record.cpu_ms.get(name, 0.0) for name in FRAME_STEPS if name != "bake"))
        self.last_frame_ms = record.total_ms
        return pose, record

    def status_line(self, found: bool) -> str:
        if not found:
            return "tag lost"
        if self.baker is None:
            return f"maps: {self.maps_label}"
        if self.baked_in_use:
            return f"maps: {self.baker.settings.method} (baked)"
        return f"maps: {self.maps_label}; baking {self.baker.settings.method} {100 * self.baker.progress:.0f} %"
