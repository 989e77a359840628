"""The capture's orientations as the SLAM community measures and exchanges trajectories, through evo: APE and
RPE of the rotation (degrees) against the truth, and TUM trajectory files (`timestamp tx ty tz qx qy qz qw`,
seconds) that `evo_ape tum trajectory_truth.tum trajectory_capture.tum` and other tools read.

The capture estimates orientations only: every position is written as 0. The orientations are the camera's
(OpenCV axes: x right, y down, z forward) to the world (+y up), at the frame times. APE is taken without any
alignment (the capture's world is the truth's); RPE over pairs of frames one second apart (round(fps) frames;
README: HDR capture). evo is imported where it is used: its import takes about 0.4 s.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.files import atomic_path

# The TUM files `arsim capture` writes, by the orientation stream each holds (CaptureResult's fields).
TRAJECTORY_FILES = {"capture": "trajectory_capture.tum", "fused": "trajectory_fused.tum", "truth": "trajectory_truth.tum"}


def pose_trajectory(t_s: np.ndarray, rotations: Rotation):
    """An evo PoseTrajectory3D of camera-to-world rotations at times t_s (seconds), positions 0."""
    from evo.core.trajectory import PoseTrajectory3D

    xyzw = rotations.as_quat()
    return PoseTrajectory3D(positions_xyz=np.zeros((len(t_s), 3)), orientations_quat_wxyz=np.roll(xyzw, 1, axis=1),
                            timestamps=np.asarray(t_s, dtype=np.float64))


def write_tum(path: Path, t_s: np.ndarray, rotations: Rotation) -> Path:
    """A TUM trajectory file (evo's writer), written atomically."""
    from evo.tools.file_interface import write_tum_trajectory_file

    with atomic_path(path) as tmp:
        write_tum_trajectory_file(str(tmp), pose_trajectory(t_s, rotations))
    return path


def rpe_delta_frames(fps: float, frames: int) -> int:
    """The RPE's step in frames: one second at the camera's frame rate, at most the recording's span."""
    return int(max(1, min(round(fps), frames - 1)))


def rotation_ape_rpe(t_s: np.ndarray, truth: Rotation, estimate: Rotation, delta_frames: int) -> dict:
    """evo's APE (per frame) and RPE (over delta_frames) of the rotation angle, degrees: RMSE, mean, max."""
    from evo.core.metrics import APE, RPE, PoseRelation, StatisticsType, Unit

    reference, estimated = pose_trajectory(t_s, truth), pose_trajectory(t_s, estimate)
    ape = APE(PoseRelation.rotation_angle_deg)
    ape.process_data((reference, estimated))
    out = {f"ape_rot_{s}_deg": float(ape.get_statistic(getattr(StatisticsType, s))) for s in ("rmse", "mean", "max")}
    if len(t_s) > 1:
        rpe = RPE(PoseRelation.rotation_angle_deg, delta_frames, Unit.frames, all_pairs=False)
        rpe.process_data((reference, estimated))
        out |= {f"rpe_rot_{s}_deg": float(rpe.get_statistic(getattr(StatisticsType, s))) for s in ("rmse", "mean", "max")}
    return out
