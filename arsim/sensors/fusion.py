"""Orientation fusion as the app reads it: a Mahony complementary filter on the noisy IMU streams.

Modes, as Android names its virtual sensors:
- `game-rotation-vector`: gyroscope and accelerometer. Gravity corrects pitch and roll; nothing
  corrects yaw, so it drifts with the gyroscope's residual bias.
- `rotation-vector`: adds the magnetometer, whose horizontal part corrects yaw towards magnetic north.

The filter integrates q' = q (omega + kp e + ki int e) / 2, where e is the cross product of the measured
and the predicted reference directions in device axes (Mahony, Hamel and Pflimlin, 2008).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.errors import ArsimError
from arsim.sensors.imu import SensorStream

MODES = ("game-rotation-vector", "rotation-vector")
UP = np.array([0.0, 1.0, 0.0])
KP = 1.0  # the accelerometer's (and magnetometer's) proportional feedback, 1/s: the tilt error decays as exp(-KP t)


def _unit(v: np.ndarray) -> np.ndarray | None:
    n = np.linalg.norm(v)
    return v / n if n > 1e-12 else None


def _sample_indices(streams: dict[str, SensorStream], mode: str):
    if mode not in MODES:
        raise ArsimError(f"fusion mode '{mode}' is unknown; use one of {', '.join(MODES)}")
    t = streams["gyroscope"].t_ns
    accel_at = np.clip(np.searchsorted(streams["accelerometer"].t_ns, t), 0, len(streams["accelerometer"].t_ns) - 1)
    mag_t = streams["magnetometer"].t_ns if mode == "rotation-vector" else t[:1]
    mag_at = np.clip(np.searchsorted(mag_t, t, side="right") - 1, 0, len(mag_t) - 1)
    return t, accel_at, mag_at


def mahony(streams: dict[str, SensorStream], start: Rotation, mode: str = "game-rotation-vector",
           kp: float = KP, ki: float = 0.0) -> tuple[np.ndarray, Rotation]:
    """Fused device-to-world orientation at every gyroscope sample: (t_ns, rotations).

    The accelerometer is read at the sample nearest in time (it runs at the gyroscope's rate by
    default), the magnetometer at its latest sample. Runs compiled (a 60 s stream is 12 000 steps);
    mahony_reference is the same filter in scipy rotations."""
    t, accel_at, mag_at = _sample_indices(streams, mode)
    use_mag = mode == "rotation-vector"
    mag = streams["magnetometer"].values if use_mag else np.zeros((1, 3))
    out = _mahony_steps(t, streams["gyroscope"].values, streams["accelerometer"].values, accel_at, mag, mag_at,
                        use_mag, start.as_quat(), kp, ki)
    return t, Rotation.from_quat(out)


@numba.njit(cache=True)
def _rotate(q, v):  # pragma: no cover (compiled)
    """v rotated by the unit quaternion q = (x, y, z, w)."""
    x, y, z, w = q[0], q[1], q[2], q[3]
    tx, ty, tz = 2.0 * (y * v[2] - z * v[1]), 2.0 * (z * v[0] - x * v[2]), 2.0 * (x * v[1] - y * v[0])
    return np.array([v[0] + w * tx + y * tz - z * ty, v[1] + w * ty + z * tx - x * tz, v[2] + w * tz + x * ty - y * tx])


@numba.njit(cache=True)
def _unit_or_zero(v):  # pragma: no cover (compiled)
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return v / n if n > 1e-12 else np.zeros(3)


@numba.njit(cache=True)
def _mahony_steps(t, gyro, accel, accel_at, mag, mag_at, use_mag, q0, kp, ki):  # pragma: no cover (compiled)
    n = t.size
    out = np.empty((n, 4))
    q = q0 / math.sqrt(np.sum(q0 * q0))
    integral = np.zeros(3)
    up = np.array([0.0, 1.0, 0.0])
    previous = t[0]
    for k in range(n):
        dt = (t[k] - previous) * 1e-9
        previous = t[k]
        inverse = np.array([-q[0], -q[1], -q[2], q[3]])
        error = np.zeros(3)
        measured_up = _unit_or_zero(accel[accel_at[k]])  # specific force points up when not accelerating
        if measured_up[0] != 0.0 or measured_up[1] != 0.0 or measured_up[2] != 0.0:
            error += np.cross(measured_up, _rotate(inverse, up))
        if use_mag:
            field_world = _rotate(q, mag[mag_at[k]])
            north = np.array([0.0, field_world[1], -math.hypot(field_world[0], field_world[2])])
            measured, predicted = _unit_or_zero(mag[mag_at[k]]), _unit_or_zero(_rotate(inverse, north))
            if np.any(measured != 0.0) and np.any(predicted != 0.0):
                error += np.cross(measured, predicted)
        integral += error * dt
        rotvec = (gyro[k] + kp * error + ki * integral) * dt
        angle = math.sqrt(rotvec[0] ** 2 + rotvec[1] ** 2 + rotvec[2] ** 2)
        # sin(angle/2)/angle, by its series where the angle is tiny (as scipy does)
        scale = 0.5 - angle * angle / 48.0 + angle**4 / 3840.0 if angle < 1e-3 else math.sin(angle / 2) / angle
        dx, dy, dz, dw = scale * rotvec[0], scale * rotvec[1], scale * rotvec[2], math.cos(angle / 2)
        x, y, z, w = q[0], q[1], q[2], q[3]
        q = np.array([w * dx + x * dw + y * dz - z * dy, w * dy - x * dz + y * dw + z * dx,
                      w * dz + x * dy - y * dx + z * dw, w * dw - x * dx - y * dy - z * dz])  # q * dq
        q /= math.sqrt(np.sum(q * q))
        out[k] = q
    return out


def mahony_reference(streams: dict[str, SensorStream], start: Rotation, mode: str = "game-rotation-vector",
                     kp: float = KP, ki: float = 0.0) -> tuple[np.ndarray, Rotation]:
    """mahony step by step with scipy rotations: the reference the compiled filter is tested against."""
    t, accel_at, mag_at = _sample_indices(streams, mode)
    gyro, accel, mag = streams["gyroscope"], streams["accelerometer"], streams["magnetometer"]
    use_mag = mode == "rotation-vector"
    q = start
    out = np.empty((len(t), 4))
    integral = np.zeros(3)
    previous = t[0]
    for k in range(len(t)):
        dt = (t[k] - previous) * 1e-9
        previous = t[k]
        error = np.zeros(3)
        to_device = q.inv()
        measured_up = _unit(accel.values[accel_at[k]])  # specific force points up when not accelerating
        if measured_up is not None:
            error += np.cross(measured_up, to_device.apply(UP))
        if use_mag:
            field_world = q.apply(mag.values[mag_at[k]])
            # Reference: the measured field's horizontal part taken as north (world -z), dip kept.
            north = np.array([0.0, field_world[1], -np.hypot(field_world[0], field_world[2])])
            measured, predicted = _unit(mag.values[mag_at[k]]), _unit(to_device.apply(north))
            if measured is not None and predicted is not None:
                error += np.cross(measured, predicted)
        integral += error * dt
        omega = gyro.values[k] + kp * error + ki * integral
        q = q * Rotation.from_rotvec(omega * dt)
        out[k] = q.as_quat()
    return t, Rotation.from_quat(out)


def yaw_error_deg(estimate: Rotation, truth: Rotation) -> np.ndarray:
    """Heading error (degrees) of estimated against true device-to-world orientations: the rotation
    about world +y that the world-frame error contains."""
    world_error = estimate * truth.inv()
    return np.degrees(world_error.as_euler("YXZ")[:, 0])


def tilt_error_deg(estimate: Rotation, truth: Rotation) -> np.ndarray:
    """Angle (degrees) between the estimated and the true up direction in device axes."""
    up_est, up_true = estimate.inv().apply(UP), truth.inv().apply(UP)
    return np.degrees(np.arccos(np.clip(np.sum(up_est * up_true, axis=1), -1.0, 1.0)))
