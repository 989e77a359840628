"""The capture run: a recording's frames linearised with the calibrated response, aligned against the
probe captured so far, and accumulated into the angle map; every orientation kept for evaluation."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from arsim.capture.accumulate import ProbeAccumulator, SensorNoise
from arsim.capture.align import Aligner
from arsim.capture.direct import DirectImages
from arsim.capture.drift import DriftFilter
from arsim.capture.refine import EarlyFeatures, GyroNoise, KeyframeFeatures, Refinement, refine, select_keyframes
from arsim.capture.response import RecoveredResponse, calibrate_response, photometric_response
from arsim.core.conventions import anglemap_disk_mask
from arsim.core.errors import ArsimError
from arsim.core.png import read_frame, read_frames, video_frame
from arsim.scenario import Scenario
from arsim.sensors.camera import SensorSettings, vignette
from arsim.sensors.frames import frame_camera_orientations, recording_camera, recording_scenario  # (re-exported)
from arsim.sensors.fusion import KP
from arsim.sensors.recording import Recording


@dataclass(frozen=True)
class CaptureSettings:
    size: int = 512  # N of the captured N x N angle map
    align_every: int = 1  # metered frames between alignments (0: never align)
    refine: bool = True  # the global rotation refinement after the online pass (README: HDR capture)

    @classmethod
    def of(cls, scenario: Scenario, size: int | None = None, align_every: int | None = None) -> CaptureSettings:
        """The scenario's [capture] settings, with the command line's overrides where given."""
        c = scenario.capture
        return cls(c.capture_size if size is None else size, c.align_every if align_every is None else align_every,
                   c.refine)


@dataclass
class CaptureResult:
    accumulator: ProbeAccumulator
    response: RecoveredResponse
    t_s: np.ndarray  # frame times (K,)
    truth: Rotation | None  # true camera-to-world per frame; None: the recording has no ground truth
    uncorrected: Rotation  # what the IMU's fused orientation says
    corrected: Rotation  # what the probe was accumulated with: refined, or the online pass's without refinement
    online: Rotation  # the online pass's (aligned against the probe so far, frame by frame)
    aligned: np.ndarray  # (K,) bool: an online alignment succeeded at this frame
    seconds: float  # processing time (reading frames included)
    seconds_online: float  # of which the online pass
    gyro_bias: tuple[np.ndarray, np.ndarray]  # the online pass's estimate of the gyroscope's residual bias
    # (device axes, rad/s) and its standard deviations
    refinement: Refinement | None = None
    # The probe as it grew: (sweep time s, SNAPSHOT_SIZE² angle map) about once a second of the final pass
    # (black where nothing was seen yet); what an app relighting as it captures would have had.
    snapshots: list = field(default_factory=list)

    @property
    def frames_per_second(self) -> float:
        return len(self.t_s) / self.seconds


def burst_response(rec: Recording, sensor: SensorSettings) -> RecoveredResponse:
    if not rec.burst:
        raise ArsimError(f"{rec.folder}: nothing to linearise its frames with: no response burst (burst.csv is empty) "
                         "and no photometric calibration; record it with [capture] burst_frames >= 2 (a bracketed burst)")
    frames = [read_frame(rec.folder / b["file"]) for b in rec.burst]
    products = np.array([b["exposure_ns"] / 1e9 * b["iso"] / sensor.base_iso for b in rec.burst])
    return calibrate_response(frames, products)


def recording_response(rec: Recording, sensor: SensorSettings) -> RecoveredResponse:
    """The camera's inverse response: the recording's photometric calibration where it carries one (TUM-VI's
    pcalib.txt, codes to 0-255 irradiance, scaled to 1 at 255), else calibrated from its burst."""
    if rec.photometric is not None:
        return photometric_response(rec.photometric.inverse_response)
    return burst_response(rec, sensor)


def recording_falloff(rec: Recording, camera, sensor: SensorSettings) -> np.ndarray:
    """The frames' vignetting: the recording's calibrated vignette where it carries one, else the sensor's."""
    if rec.photometric is not None:
        return rec.photometric.vignette.astype(np.float64)
    return vignette(camera.height, camera.width, sensor.vignetting)


def fused_camera_orientations(rec: Recording) -> Rotation:
    """The app's camera-to-world orientation at each frame time: the fused device orientation
    (interpolated) times the camera mount."""
    t_ns, fused = rec.orientation
    t = np.clip([f["t_ns"] for f in rec.frames], t_ns[0], t_ns[-1])
    return Slerp(t_ns.astype(np.float64), fused)(t.astype(np.float64)) * Rotation.from_matrix(np.array(rec.meta["camera_to_device"]))


def _check_overlap(rec: Recording, orientations: Rotation, camera) -> None:
    """Refuse a recording none of whose consecutive frames overlap (as the IMU sees them): nothing in it can
    be aligned, and the probe would be a scatter of single views."""
    if len(orientations) < 2:
        return
    axes = orientations.apply([0.0, 0.0, 1.0])
    turns = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", axes[:-1], axes[1:]), -1.0, 1.0)))
    fov = np.degrees(2 * np.arctan(0.5 * min(camera.width / camera.fx, camera.height / camera.fy)))
    if np.all(turns >= fov):
        raise ArsimError(f"{rec.folder}: no two consecutive frames overlap (the view turns {np.median(turns):.0f} degrees "
                         f"between frames, more than the camera's {fov:.0f}-degree field of view); record with more "
                         "frames per second or a slower sweep")


def new_accumulator(size: int, camera, falloff: np.ndarray, sensor: SensorSettings, levels: int) -> ProbeAccumulator:
    """An empty size x size angle map for the recording's frames, with the sensor's noise figures (for the
    correction of the noise clipped at code 0)."""
    return ProbeAccumulator(size, camera, falloff, levels=levels, sensor=SensorNoise(sensor.full_well_e, sensor.read_noise_e))


def gains(rec: Recording, sensor: SensorSettings) -> list[float]:
    """Each frame's analog gain: its ISO over the base ISO."""
    return [f["iso"] / sensor.base_iso for f in rec.frames]


def exposure_scales(rec: Recording, sensor: SensorSettings) -> list[float]:
    """Each frame's exposure (time x ISO / base ISO x the sensor's sensitivity): radiance x this is what its
    codes encode."""
    return [f["exposure_ns"] / 1e9 * f["iso"] / sensor.base_iso * sensor.sensitivity for f in rec.frames]


# With the refinement, the share of the capture's progress its online pass and its refinement take (the rest: the
# frames accumulated again), as their times on the default sweep split
ONLINE_SHARE, REFINE_SHARE = 0.4, 0.45
SNAPSHOT_SIZE = 32  # the growing probe's snapshots (SH to band 9 need no more)
# The online pass keeps the frames it decoded, up to this many bytes, for the refined pass to accumulate
# again instead of decoding them a second time (the default sweep: 1814 frames, 1.7 GB; decoding them again
# took 7 s of CPU on two busy cores); beyond it the rest are read again.
KEEP_DECODED_BYTES = 2 * 1024**3


def probe_snapshot(accumulator: ProbeAccumulator, size: int = SNAPSHOT_SIZE) -> np.ndarray:
    """The probe captured so far as a small angle map: the disk's texels area-averaged (the rim's partial
    texels over their share of the disk), 0 where nothing was seen."""
    probe = accumulator.probe()
    disk = anglemap_disk_mask(probe.shape[0]).astype(np.float32)
    total = cv2.resize(probe * disk[..., None], (size, size), interpolation=cv2.INTER_AREA)
    share = cv2.resize(disk, (size, size), interpolation=cv2.INTER_AREA)[..., None]
    return np.where(share > 0, total / np.maximum(share, 1e-12), 0.0) * anglemap_disk_mask(size)[..., None]


def _second_ends(times: np.ndarray, k: int) -> bool:
    """Whether frame k is the last of a whole second of the sweep (times from its start), or the last one."""
    return k == len(times) - 1 or int(times[k] - times[0]) < int(times[k + 1] - times[0])


def _frames(files: list, decoded: list, check: bool):
    """Each frame's codes in order: decoded[k] where kept (released as it is given), else read."""
    missing = iter(read_frames([f for f, codes in zip(files, decoded) if codes is None], check=check))
    for k in range(len(files)):
        codes, decoded[k] = decoded[k], None
        yield next(missing) if codes is None else codes


def accumulate_frames(rec: Recording, orientations: Rotation, response: RecoveredResponse, size: int,
                      progress: Callable[[float, float], None] = lambda fraction, coverage: None,
                      snapshots: list | None = None, checked: bool = False,
                      decoded: list | None = None) -> ProbeAccumulator:
    """Every frame of the recording accumulated into a size x size angle map at the given camera-to-world
    orientations (K,), linearised with the response: the refined pass, or (true orientations, true
    response) the ideal merge that bounds what any capture of the same frames can do. snapshots: a list
    that gets (time s, probe_snapshot) about once a second and at the end. checked: the frames were read and
    checked before by this process (core.png.png_problem is not run again). decoded: per frame its codes
    where an earlier pass kept them (None where not), emptied as they are used."""
    scenario = recording_scenario(rec)
    bracket = scenario.capture.bracket_ev
    sensor = SensorSettings.of(scenario.device.camera)
    camera = recording_camera(rec)
    levels = sorted(set(bracket), reverse=True)
    accumulator = new_accumulator(size, camera, recording_falloff(rec, camera, sensor), sensor, len(levels))
    files, scales, gain = [rec.folder / f["file"] for f in rec.frames], exposure_scales(rec, sensor), gains(rec, sensor)
    times = np.array([f["t_ns"] for f in rec.frames]) / 1e9
    for k, codes in enumerate(_frames(files, decoded or [None] * len(files), not checked)):
        accumulator.add(codes, response.linear / scales[k], orientations[k].as_matrix(), scales[k],
                        levels.index(bracket[k % len(bracket)]), gain[k])
        if snapshots is not None and _second_ends(times, k):
            snapshots.append((float(times[k] - times[0]), probe_snapshot(accumulator)))
        if k % 30 == 0 or k == len(rec.frames) - 1:
            progress((k + 1) / len(rec.frames), accumulator.coverage())
    return accumulator


def capture(rec: Recording, settings: CaptureSettings | None = None,
            progress: Callable[[float, float], None] = lambda fraction, coverage: None) -> CaptureResult:
    """Run the capture on a recording (settings: the recording's scenario's unless given);
    progress(fraction done, coverage so far)."""
    if not rec.frames:
        raise ArsimError(f"{rec.folder}: the recording has no frames; record a sweep first")
    scenario = recording_scenario(rec)
    settings = settings or CaptureSettings.of(scenario)
    bracket = scenario.capture.bracket_ev  # frame k was taken at offset bracket[k % len]; 0: metered
    sensor = SensorSettings.of(scenario.device.camera)
    camera = recording_camera(rec)
    falloff = recording_falloff(rec, camera, sensor)
    files = [rec.folder / f["file"] for f in rec.frames]
    uncorrected = fused_camera_orientations(rec)
    times = np.array([f["t_ns"] for f in rec.frames]) / 1e9
    early = None
    # (the refinement's keyframes: its metered frames, as below; not from a video, whose frames out of order each
    # cost a seek: the quick sweep's capture 21.6 s against 17.7 s)
    if settings.refine and settings.align_every and video_frame(files[0]) is None:
        keys = select_keyframes(np.arange(0, len(files), len(bracket)), uncorrected, times)
        early = EarlyFeatures(camera, keys, lambda k: read_frame(files[k]))
    try:
        return _capture(rec, settings, progress, scenario, bracket, sensor, camera, falloff, files, uncorrected, times,
                        early)
    finally:
        if early is not None:
            early.stop()


def _capture(rec: Recording, settings: CaptureSettings, progress, scenario: Scenario, bracket, sensor: SensorSettings,
             camera, falloff: np.ndarray, files: list, uncorrected: Rotation, times: np.ndarray,
             early: EarlyFeatures | None) -> CaptureResult:
    """capture's work once the keyframes' features are being found (early)."""
    response = recording_response(rec, sensor)
    exposure_levels = sorted(set(bracket), reverse=True)  # the accumulator's levels, longest exposure first
    accumulator = new_accumulator(settings.size, camera, falloff, sensor, len(exposure_levels))
    aligner = Aligner(camera, falloff, response, scenario.run.seed)
    truth = frame_camera_orientations(rec) if rec.groundtruth is not None else None
    _check_overlap(rec, uncorrected, camera)
    gyro_noise = GyroNoise.of(scenario.device.gyroscope)
    corrected, aligned = [], np.zeros(len(rec.frames), dtype=bool)
    accelerometer = scenario.device.accelerometer
    drift = DriftFilter(uncorrected, times, gyro_noise, accelerometer.turn_on_bias + accelerometer.bias_instability, KP,
                        scenario.capture.fusion == "rotation-vector", settings.size)
    start = time.perf_counter()
    any_unclipped = False
    final_online, online_snapshots = not settings.refine or not settings.align_every, []
    features = KeyframeFeatures(camera)
    metered_small: dict[int, np.ndarray] = {}  # what the refinement's keyframes are taken from
    scales, gain = exposure_scales(rec, sensor), gains(rec, sensor)
    decoded, kept_bytes = [None] * len(files), 0  # (for the refined pass)
    for k, codes in enumerate(read_frames(files)):  # (decoded ahead, overlapping the alignment)
        if settings.refine and settings.align_every and kept_bytes + codes.nbytes <= KEEP_DECODED_BYTES:
            decoded[k], kept_bytes = codes, kept_bytes + codes.nbytes
        any_unclipped = any_unclipped or bool(np.any(codes < 255))
        exposure_scale = scales[k]
        drift.predict(k)
        predicted = drift.correction() * uncorrected[k]
        metered, index = divmod(k, len(bracket))
        if index == 0 and settings.refine:
            metered_small[k] = features.small(codes)
        # Only metered frames are aligned: the bracketed ones are dark but for the highlights.
        if settings.align_every and index == 0 and metered % settings.align_every == 0 and k > 0:
            found = aligner.align(codes, accumulator, predicted.as_matrix(), exposure_scale)
            # A match further from the prediction than the filter's uncertainty allows is a false match
            # (few features, repeated patterns): it is dropped like a failed one.
            if found.rotation is not None and drift.update(predicted * found.rotation):
                aligned[k] = True
                predicted = drift.correction() * uncorrected[k]
        corrected.append(predicted)
        # With the refined pass to come, this probe only serves the alignment, which renders it at the metered
        # exposure: the bracketed frames, dark but for highlights that render clipped there, are left out of it.
        if final_online or index == 0:
            accumulator.add(codes, response.linear / exposure_scale, predicted.as_matrix(), exposure_scale,
                            exposure_levels.index(bracket[index]), gain[k])
        if final_online and _second_ends(times, k):  # (the online probe is the final one: its growth kept)
            online_snapshots.append((float(times[k] - times[0]), probe_snapshot(accumulator)))
        if k % 30 == 0 or k == len(rec.frames) - 1:
            progress((k + 1) / len(rec.frames) * (ONLINE_SHARE if settings.refine else 1.0), accumulator.coverage())
    if not any_unclipped:
        raise ArsimError(f"{rec.folder}: every frame is saturated (all codes 255); nothing can be captured from it")
    online = Rotation.concatenate(corrected)
    seconds_online = time.perf_counter() - start
    mount = np.array(rec.meta["camera_to_device"])
    bias, bias_sigma = drift.bias  # camera axes: the gyroscope's are the device's
    gyro_bias = (mount @ bias, np.sqrt(mount**2 @ bias_sigma**2))
    if not settings.refine or not settings.align_every:
        return CaptureResult(accumulator, response, times, truth, uncorrected, online, online, aligned,
                             seconds_online, seconds_online, gyro_bias, snapshots=online_snapshots)
    # The refined pass: every keyframe orientation at once, then the frames accumulated again with them.
    gyro = rec.imu["gyroscope"]
    refinement = refine(times, np.array(sorted(metered_small)), uncorrected, metered_small.__getitem__,
                        scenario.device.camera.hfov_deg, camera, gyro_noise,
                        scenario.run.seed, (gyro.t_ns, gyro.values, Rotation.from_matrix(mount)),
                        DirectImages(features.camera, camera, response.linear, falloff),
                        lambda fraction: progress(ONLINE_SHARE + REFINE_SHARE * fraction, accumulator.coverage()), early)
    # with no keyframe pair the refinement has only the IMU's orientations: the online pass's, with the bias its
    # filter learnt from whatever it aligned, are no worse
    final = refinement.orientations if refinement.loop_closures else online
    snapshots = []
    accumulator = accumulate_frames(rec, final, response, settings.size,
                                    lambda fraction, coverage: progress(ONLINE_SHARE + REFINE_SHARE
                                                                        + (1 - ONLINE_SHARE - REFINE_SHARE) * fraction,
                                                                        coverage), snapshots,
                                    checked=True, decoded=decoded)  # (the online pass read and checked every frame)
    return CaptureResult(accumulator, response, times, truth, uncorrected, final, online, aligned,
                         time.perf_counter() - start, seconds_online, gyro_bias, refinement, snapshots)
