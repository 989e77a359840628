"""The tracker measured against the truth on an AR recording: per frame, the error of the camera's
rotation (degrees) and position (millimetres, and percent of its distance to the tag), whether the tag
was fully in view, and whether it was found (without a ground truth: only whether it was found)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.png import read_frame
from arsim.core.tags import DEFAULT_DETECTOR
from arsim.evaluate.capture_report import orientation_errors_deg
from arsim.evaluate.recording_plots import tag_in_view
from arsim.sensors.frames import NO_GROUNDTRUTH, frame_camera_orientations, frame_positions
from arsim.sensors.recording import Recording
from arsim.tracking.apriltag import TagPose
from arsim.tracking.fusion import recording_tracker


@dataclass
class TrackingRun:
    poses: list[TagPose]
    # The four below are None where the recording has no ground truth (nothing to measure against).
    visible: np.ndarray | None  # (K,) bool: all four corners of the tag inside the frame (true pose)
    rot_err_deg: np.ndarray | None  # (K,) inf where the tag was not found
    trans_err_mm: np.ndarray | None  # (K,) camera position error, inf where not found
    trans_err_pct: np.ndarray | None  # (K,) the same in percent of the camera's true distance to the tag

    @property
    def measured(self) -> bool:
        """Whether the poses were measured against a ground truth."""
        return self.visible is not None

    @property
    def found(self) -> np.ndarray:
        """(K,) bool: a pose was given (and objects drawn): detected, or extrapolated by the IMU fusion."""
        return np.array([p.found for p in self.poses])

    @property
    def extrapolated(self) -> np.ndarray:
        return np.array([p.found and p.extrapolated for p in self.poses])

    def metrics(self) -> dict:
        """Summary: the 95th percentiles over the frames where the tag was fully visible (a visible
        tag not found counts as an infinite error, so the percentile is infinite where more than 5 % of
        them were lost: null in JSON), frame counts and the detection rate. Without a ground truth, only what
        needs none: the frame counts, lost and extrapolated, and "truth" saying why the rest is absent."""
        found = self.found
        if not self.measured:
            extrapolated = self.extrapolated
            return {"frames_total": int(len(found)), "frames_lost": int((~found).sum()),
                    "frames_extrapolated": int(extrapolated.sum()),
                    "extrapolated_s_max": max((p.since_tag_s for p in self.poses if p.found and p.extrapolated), default=0.0),
                    "truth": {"groundtruth": NO_GROUNDTRUTH}}
        visible = self.visible
        # (the "higher" rule takes a frame's error: interpolating between two infinite errors gives NaN)
        p95 = (lambda a: float(np.percentile(a[visible], 95, method="higher")) if visible.any() else float("nan"))
        return {
            "tracking_rot_err_deg_p95": p95(self.rot_err_deg),
            "tracking_trans_err_pct_p95": p95(self.trans_err_pct),
            "tracking_trans_err_mm_p95": p95(self.trans_err_mm),
            "frames_total": int(len(found)),
            "frames_lost": int((~found).sum()),
            "frames_tag_visible": int(visible.sum()),
            "detection_rate_visible": float(found[visible].mean()) if visible.any() else float("nan"),
            "found_while_not_visible": int((found & ~visible).sum()),
            # the IMU fusion's poses without a tag: how many, for how long at the most, and their errors
            "frames_extrapolated": int(self.extrapolated.sum()),
            "extrapolated_s_max": max((p.since_tag_s for p in self.poses if p.found and p.extrapolated), default=0.0),
            "extrapolated_rot_err_deg_p95": _p95(self.rot_err_deg[self.extrapolated]),
            "extrapolated_trans_err_pct_p95": _p95(self.trans_err_pct[self.extrapolated]),
        }


def _p95(values: np.ndarray) -> float | None:
    return float(np.percentile(values, 95, method="higher")) if len(values) else None


def measure_poses(rec: Recording, poses: list[TagPose], frames: np.ndarray | None = None) -> TrackingRun:
    """Tracked poses of an AR recording's frames (all, or those at the indices `frames`) against the truth."""
    frames = np.arange(len(rec.frames)) if frames is None else np.asarray(frames)
    if rec.groundtruth is None:
        return TrackingRun(poses, None, None, None, None)
    views, positions = frame_camera_orientations(rec)[frames], frame_positions(rec)[frames]
    rot, mm, pct = [], [], []
    for k, pose in enumerate(poses):
        if pose.found:
            rot.append(float(orientation_errors_deg(Rotation.from_matrix(pose.rotation.T), views[k])))
            # (lengths term by term: np.linalg.norm's BLAS dot rounds by the arrays' alignment in memory)
            error = math.hypot(*(pose.camera_position - positions[k]))
            mm.append(1000 * error)
            pct.append(100 * error / math.hypot(*positions[k]))
        else:
            rot.append(np.inf), mm.append(np.inf), pct.append(np.inf)
    return TrackingRun(poses, tag_in_view(rec)[frames], np.array(rot), np.array(mm), np.array(pct))


def track_recording(rec: Recording, linear_of_code: np.ndarray | None = None,
                    progress: Callable[[float], None] = lambda fraction: None, detector: str = DEFAULT_DETECTOR,
                    fusion: bool = False) -> TrackingRun:
    """Track the tag through an AR recording's frames with a detector by name (fused with the IMU where
    fusion is set) and measure every pose against the truth; linear_of_code: the camera's inverse response
    (256,), e.g. the capture's, to linearise the frames."""
    tracker = recording_tracker(rec, linear_of_code, detector, fusion)
    poses = []
    for k, frame in enumerate(rec.frames):
        poses.append(tracker.track(read_frame(rec.folder / frame["file"]), k))
        if k % 20 == 0:
            progress((k + 1) / len(rec.frames))
    progress(1.0)
    return measure_poses(rec, poses)
