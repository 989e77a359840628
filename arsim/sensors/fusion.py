"""Orientation fusion as the app reads it: a Mahony complementary filter on the noisy IMU streams.

Modes, as Android names its virtual sensors:
- `game-rotation-vector`: gyroscope and accelerometer. Gravity corrects pitch and roll; nothing
  corrects yaw, so it drifts with the gyroscope's residual bias.
- `rotation-vector`: adds the magnetometer, whose horizontal part corrects yaw towards magnetic north.

The filter integrates q' = q (omega + kp e + ki int e) / 2, where e is the cross product of the measured
and the predicted reference directions in device axes (Mahony, Hamel and Pflimlin, 2008).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.core.errors import ArsimError
from arsim.sensors.imu import SensorStream

MODES = ("game-rotation-vector", "rotation-vector")
UP = np.array([0.0, 1.0, 0.0])


def _unit(v: np.ndarray) -> np.ndarray | None:
    n = np.linalg.norm(v)
    return v / n if n > 1e-12 else None


def mahony(streams: dict[str, SensorStream], start: Rotation, mode: str = "game-rotation-vector",
           kp: float = 1.0, ki: float = 0.0) -> tuple[np.ndarray, Rotation]:
    """Fused device-to-world orientation at every gyroscope sample: (t_ns, rotations).

    The accelerometer is read at the sample nearest in time (it runs at the gyroscope's rate by
    default), the magnetometer at its latest sample."""
    if mode not in MODES:
        raise ArsimError(f"fusion mode '{mode}' is unknown; use one of {', '.join(MODES)}")
    gyro, accel = streams["gyroscope"], streams["accelerometer"]
    t = gyro.t_ns
    accel_at = np.clip(np.searchsorted(accel.t_ns, t), 0, len(accel.t_ns) - 1)
    use_mag = mode == "rotation-vector"
    if use_mag:
        mag = streams["magnetometer"]
        mag_at = np.clip(np.searchsorted(mag.t_ns, t, side="right") - 1, 0, len(mag.t_ns) - 1)
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
