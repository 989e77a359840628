"""What a recording's frames saw: the camera they were taken with, the scenario its sensors are described by,
and the ground truth (orientation and position) at the frame times, where the recording has one. Every stage
that compares with the truth, or projects through the camera, reads them from here.

A recording arsim did not synthesise (a phone's, a data set's) has no groundtruth.csv, and no scenario_toml in
its meta.json: `truth_absent` says which of the two truths is missing and what is left out for it, and
`recording_scenario` gives the default scenario's sensor settings in place of the missing scenario (every frame
metered)."""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from arsim.core.conventions import CameraIntrinsics
from arsim.core.errors import ArsimError
from arsim.scenario import Scenario
from arsim.scenario.loader import load_scenario, parse_scenario
from arsim.scenario.sections import EnvironmentSection
from arsim.sensors.recording import Recording

# The two truths a recording may hold, and what is left out without each (metrics.json's "truth" and the
# report say it in these words).
NO_GROUNDTRUTH = ("absent: the recording has no groundtruth.csv (the true device poses), so the orientation "
                  "and tracking errors are left out")
NO_SCENARIO = ("absent: the recording's meta.json has no scenario_toml, so the true environment and camera response "
               "are unknown: the probe's, the maps', the response's, the frames' and the light estimates' errors "
               "are left out (the default scenario's sensor settings stand in for the recording's)")


def recording_scenario(rec: Recording) -> Scenario:
    """The scenario a recording was made from (its meta.json keeps it); for a recording without one, the
    default scenario (arsim/scenario/default.toml), whose [capture] and [device] settings then describe
    the sensors, but for the exposure brackets: every frame is taken as metered ([capture] bracket_ev =
    [0.0]). The brackets cycling through the sweep are arsim's recorder's; a camera's own stream has none
    (its exposures are frames.csv's either way)."""
    text = rec.meta.get("scenario_toml")
    if text is None:
        scenario = load_scenario(None)
        return dataclasses.replace(scenario, capture=dataclasses.replace(scenario.capture, bracket_ev=(0.0,)))
    return parse_scenario(text, str(rec.folder / "meta.json"), rec.folder)


def true_environment(rec: Recording) -> EnvironmentSection | None:
    """The true environment the recording saw ([environment] of its scenario); None where it is unknown."""
    return recording_scenario(rec).environment if "scenario_toml" in rec.meta else None


def truth_absent(rec: Recording) -> dict[str, str]:
    """What of the truth the recording lacks, each with what is left out for it: "groundtruth" (the device
    poses), "scenario" (the true environment and camera response). Empty for arsim's own recordings."""
    absent = {}
    if rec.groundtruth is None:
        absent["groundtruth"] = NO_GROUNDTRUTH
    if "scenario_toml" not in rec.meta:
        absent["scenario"] = NO_SCENARIO
    return absent


def _groundtruth(rec: Recording) -> tuple:
    if rec.groundtruth is None:  # (callers check truth_absent first; this guards one that does not)
        raise ArsimError(f"{rec.folder}: the recording has no groundtruth.csv; nothing can be measured against the "
                         "true poses")
    return rec.groundtruth


def recording_camera(rec: Recording) -> CameraIntrinsics:
    """The intrinsics the recording's frames were taken with (its meta.json)."""
    cam = rec.meta["camera"]
    return CameraIntrinsics(cam["width"], cam["height"], cam["fx"], cam["fy"], cam["cx"], cam["cy"],
                            cam.get("k1", 0.0), cam.get("k2", 0.0))


def frame_times_ns(rec: Recording) -> np.ndarray:
    """The frame times clipped to the ground truth's span (float64 ns)."""
    t_truth = _groundtruth(rec)[0]
    return np.clip(np.array([f["t_ns"] for f in rec.frames], dtype=np.float64), t_truth[0], t_truth[-1])


def frame_camera_orientations(rec: Recording) -> Rotation:
    """True camera-to-world rotations at the frame times, slerped between the ground truth's samples (taken
    at the gyroscope's jittered times: the nearest sample is up to 5 ms off at 200 Hz, 0.27 degrees at the
    capture sweep's 54 degrees/s)."""
    t_truth, _, truth = _groundtruth(rec)
    return Slerp(t_truth.astype(np.float64), truth)(frame_times_ns(rec)) * Rotation.from_matrix(np.array(rec.meta["camera_to_device"]))


def frame_positions(rec: Recording) -> np.ndarray:
    """True device positions (K, 3) at the frame times, interpolated linearly between the ground truth's samples."""
    t_truth, positions, _ = _groundtruth(rec)
    t_truth = t_truth.astype(np.float64)
    t = frame_times_ns(rec)
    return np.stack([np.interp(t, t_truth, positions[:, i]) for i in range(3)], axis=-1)


def check_frame_pixels(rec: Recording, progress=lambda fraction: None) -> int:
    """Decode every frame and burst frame of a recording (load_recording reads only their headers): one
    ArsimError naming the first that cannot be decoded or is not the camera's size; returns the count."""
    import os

    from arsim.core.png import read_frames

    cam = rec.meta["camera"]
    files = [f["file"] for f in rec.frames] + [b["file"] for b in rec.burst]
    decoded = read_frames((rec.folder / name for name in files), workers=os.cpu_count() or 1)
    for k, (name, frame) in enumerate(zip(files, decoded)):
        shape = frame.shape[:2]
        if shape != (cam["height"], cam["width"]):
            raise ArsimError(f"{rec.folder / name}: decodes to {shape[1]} x {shape[0]}, the camera's frames "
                             f"are {cam['width']} x {cam['height']}; record again")
        if k % 64 == 0:
            progress(k / len(files))
    progress(1.0)
    return len(files)
