"""What the standard layouts share: the photometric calibration a recording may carry, the arsim extras that
make a round trip exact (files a plain EuRoC or ROS reader ignores), the IMU merged onto common timestamps,
and what a recording from elsewhere lacks (its fused orientation, its exposure) filled in as the app would."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.errors import ArsimError
from arsim.sensors.fusion import mahony
from arsim.sensors.imu import SensorStream
from arsim.sensors.recording import FORMAT, Recording

# meta.json's keys a layout holds in its own files (the camera's sensor.yaml or CameraInfo); the arsim extras
# keep the rest. source_format is the reader's note of where a recording came from (never written).
LAYOUT_KEYS = ("format", "camera", "camera_to_device", "source_format")
DEFAULT_FUSION = "game-rotation-vector"
# A recording from elsewhere without exposure times (EuRoC has none): every frame taken as equally exposed,
# at this time and unit gain (the capture's radiance is then relative, as it is for any uncalibrated camera).
FOREIGN_EXPOSURE_NS, FOREIGN_ISO = 10_000_000, 100.0


@dataclass(frozen=True, eq=False)
class Photometric:
    """A camera's photometric calibration as TUM-VI ships it (DSO's pcalib.txt and vignette.png)."""

    inverse_response: np.ndarray  # (256,) float64: each 8-bit code's irradiance, 0 to 255 at full scale (pcalib.txt)
    vignette: np.ndarray  # (H, W) float32: each pixel's attenuation, 1 where the lens passes the most

    def check(self, width: int, height: int, where: str) -> None:
        inv, v = self.inverse_response, self.vignette
        if inv.shape != (256,) or not np.isfinite(inv).all() or (np.diff(inv) < 0).any() or inv[-1] <= 0:
            raise ArsimError(f"{where}: the inverse response is not 256 finite, non-decreasing values ending above 0; "
                             "give pcalib.txt as TUM-VI's (one line of 256 numbers)")
        if v.shape != (height, width) or not np.isfinite(v).all() or v.min() <= 0 or v.max() > 1.0 + 1e-6:
            raise ArsimError(f"{where}: the vignette is {v.shape[1]} x {v.shape[0]} with values "
                             f"{float(v.min()):.3g} to {float(v.max()):.3g}; give one of the camera's {width} x {height} "
                             "pixels with values in (0, 1]")


def exact_rotations(q: np.ndarray, where: str) -> Rotation:
    """Quaternions (K, 4; x, y, z, w) as rotations, each kept as written where it is unit to 1e-8 (as a file's
    9 decimals are: normalising them again moves their last bits, and a second export would differ), normalised
    where it is further off; a zero quaternion refused."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    norms = np.linalg.norm(q, axis=1)
    if (norms < 1e-6).any():
        raise ArsimError(f"{where}: entry {int(np.flatnonzero(norms < 1e-6)[0]) + 1} is a zero quaternion")
    off = np.abs(norms - 1.0) > 1e-8
    return Rotation(np.where(off[:, None], q / norms[:, None], q), normalize=False)


def merged_imu(imu: dict[str, SensorStream]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The gyroscope and accelerometer at common timestamps, as EuRoC's imu0 and a ROS Imu message hold them:
    the gyroscope's own samples and times, the accelerometer interpolated linearly to them (held at its first
    and last value beyond its span). Returns t_ns (K,), gyroscope (K, 3), accelerometer (K, 3)."""
    gyro, accel = imu["gyroscope"], imu["accelerometer"]
    if not len(gyro.t_ns) or not len(accel.t_ns):
        return gyro.t_ns, gyro.values, np.zeros((len(gyro.t_ns), 3))
    t = gyro.t_ns.astype(np.float64)
    at = accel.t_ns.astype(np.float64)
    return gyro.t_ns, gyro.values, np.stack([np.interp(t, at, accel.values[:, i]) for i in range(3)], axis=-1)


def imu_streams(t_ns: np.ndarray, gyro: np.ndarray, accel: np.ndarray, raw: dict[str, SensorStream] | None) -> dict:
    """The IMU streams of a recording read from a layout: the gyroscope from the common file, the accelerometer
    and magnetometer as measured where the arsim extras keep them (raw), else the accelerometer at the common
    timestamps and no magnetometer."""
    raw = raw or {}
    empty = SensorStream("magnetometer", np.zeros(0, np.int64), np.zeros((0, 3)))
    return {"gyroscope": SensorStream("gyroscope", t_ns, gyro),
            "accelerometer": raw.get("accelerometer") or SensorStream("accelerometer", t_ns, accel),
            "magnetometer": raw.get("magnetometer") or empty}


def fused_orientation(imu: dict[str, SensorStream], groundtruth, fusion: str, where: str) -> tuple[np.ndarray, Rotation]:
    """What the app's fusion reports for a recording that does not carry it: the Mahony filter over its IMU
    (README: Synthetic sensors), started at the ground truth's first orientation, or without one level with
    the first accelerometer sample (its heading is then arbitrary, as a game rotation vector's is)."""
    gyro, accel = imu["gyroscope"], imu["accelerometer"]
    if len(gyro.t_ns) < 2 or not len(accel.t_ns):
        raise ArsimError(f"{where}: the IMU holds {len(gyro.t_ns)} gyroscope and {len(accel.t_ns)} accelerometer "
                         "samples; the orientation needs at least 2 and 1")
    if groundtruth is not None:
        start = groundtruth[2][0]
    else:
        up = accel.values[0]
        if np.linalg.norm(up) < 1e-6:
            raise ArsimError(f"{where}: the first accelerometer sample is zero; the orientation cannot be levelled")
        start = Rotation.align_vectors([[0.0, 1.0, 0.0]], [up])[0]  # arsim's world: +y up
    if fusion == "rotation-vector" and not len(imu["magnetometer"].t_ns):
        fusion = DEFAULT_FUSION
    return mahony(imu, start, fusion)


def recording_of(folder: Path, meta: dict, frames: list[dict], burst: list[dict], imu: dict,
                 orientation, groundtruth, photometric: Photometric | None) -> Recording:
    """A Recording read from a layout (its frame and burst files relative to folder)."""
    kwargs = {"photometric": photometric} if photometric is not None else {}
    return Recording(folder, meta, frames, burst, imu, orientation, groundtruth, **kwargs)


def layout_meta(camera: dict, camera_to_device: list, extras: dict | None, frames: list[dict], imu: dict,
                source_format: str) -> dict:
    """meta.json of a recording read from a layout: the layout's camera, then the arsim extras' keys in their
    order (so that a second export writes them again byte for byte); a recording from elsewhere gets seed 0,
    its duration from its frames and the default fusion, and no scenario (no known true environment)."""
    meta = {"format": FORMAT, "camera": camera, "camera_to_device": camera_to_device}
    if extras is not None:
        meta |= {k: v for k, v in extras.items() if k not in LAYOUT_KEYS}
    else:
        times = [f["t_ns"] for f in frames] or list(imu["gyroscope"].t_ns[[0, -1]])
        meta |= {"seed": 0, "duration_s": max((int(times[-1]) - int(times[0])) / 1e9, 1e-9), "fusion": DEFAULT_FUSION}
    meta["source_format"] = source_format
    return meta


def extras_meta(meta: dict) -> dict:
    return {k: v for k, v in meta.items() if k not in LAYOUT_KEYS}
