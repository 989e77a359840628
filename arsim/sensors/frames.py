"""What a recording's frames saw: the camera they were taken with, and the ground truth (orientation and
position) at the frame times. Every stage that compares with the truth, or projects through the camera, reads
them from here."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from arsim.core.conventions import CameraIntrinsics
from arsim.core.errors import ArsimError
from arsim.sensors.recording import Recording


def recording_camera(rec: Recording) -> CameraIntrinsics:
    """The intrinsics the recording's frames were taken with (its meta.json)."""
    cam = rec.meta["camera"]
    return CameraIntrinsics(cam["width"], cam["height"], cam["fx"], cam["fy"], cam["cx"], cam["cy"],
                            cam.get("k1", 0.0), cam.get("k2", 0.0))


def frame_times_ns(rec: Recording) -> np.ndarray:
    """The frame times clipped to the ground truth's span (float64 ns)."""
    t_truth = rec.groundtruth[0]
    return np.clip(np.array([f["t_ns"] for f in rec.frames], dtype=np.float64), t_truth[0], t_truth[-1])


def frame_camera_orientations(rec: Recording) -> Rotation:
    """True camera-to-world rotations at the frame times, slerped between the ground truth's samples (taken
    at the gyroscope's jittered times: the nearest sample is up to 5 ms off at 200 Hz, 0.27 degrees at the
    capture sweep's 54 degrees/s)."""
    t_truth = rec.groundtruth[0].astype(np.float64)
    return Slerp(t_truth, rec.groundtruth[2])(frame_times_ns(rec)) * Rotation.from_matrix(np.array(rec.meta["camera_to_device"]))


def frame_positions(rec: Recording) -> np.ndarray:
    """True device positions (K, 3) at the frame times, interpolated linearly between the ground truth's samples."""
    t_truth, positions = rec.groundtruth[0].astype(np.float64), rec.groundtruth[1]
    t = frame_times_ns(rec)
    return np.stack([np.interp(t, t_truth, positions[:, i]) for i in range(3)], axis=-1)


def check_frame_pixels(rec: Recording, progress=lambda fraction: None) -> int:
    """Decode every frame and burst frame of a recording (load_recording reads only their headers): one
    ArsimError naming the first that cannot be decoded or is not the camera's size; returns the count."""
    import os
    from concurrent.futures import ThreadPoolExecutor

    from arsim.core.png import read_frame

    cam = rec.meta["camera"]
    files = [f["file"] for f in rec.frames] + [b["file"] for b in rec.burst]

    def size(name: str) -> tuple[int, int]:
        return read_frame(rec.folder / name).shape[:2]

    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:  # (OpenCV decodes without the GIL)
        for k, (name, shape) in enumerate(zip(files, pool.map(size, files))):
            if shape != (cam["height"], cam["width"]):
                raise ArsimError(f"{rec.folder / name}: decodes to {shape[1]} x {shape[0]}, the camera's frames "
                                 f"are {cam['width']} x {cam['height']}; record again")
            if k % 64 == 0:
                progress(k / len(files))
    progress(1.0)
    return len(files)
