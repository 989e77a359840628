"""Ground-truth device trajectories with exact derivatives, so that the IMU is consistent with them.

Device axes are Android's: x right, y up along the screen, z out of the screen towards the user; the
back camera looks along -z. Orientation R(t) maps device to world coordinates (world: +y up). The
orientation is a yaw-pitch-roll composition R = Ry(yaw) Rx(pitch) Rz(roll) of smooth angle functions,
whose angular velocity is known in closed form:
    omega_world = yaw' e_y + pitch' Ry e_x + roll' Ry Rx e_z,    omega_device = R^T omega_world.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

GRAVITY = np.array([0.0, -9.80665, 0.0])  # m/s², world frame

# Camera (OpenCV: x right, y down, z forward) to device axes (Android): the back camera looks along -z.
CAMERA_TO_DEVICE = np.diag([1.0, -1.0, -1.0])


def camera_mount(misalignment_deg=(0.0, 0.0, 0.0)) -> Rotation:
    """Camera-to-device rotation: the nominal back-camera mount, then a small misalignment (x, y, z
    degrees, about the camera's own axes)."""
    return Rotation.from_matrix(CAMERA_TO_DEVICE) * Rotation.from_euler("xyz", misalignment_deg, degrees=True)


def _smoothstep(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Quintic ease 6u^5 - 15u^4 + 10u^3 on [0, 1] and its first two derivatives (zero at both ends)."""
    u = np.clip(u, 0.0, 1.0)
    return (u**3 * (10 - 15 * u + 6 * u * u), 30 * u * u * (1 - u) ** 2, 60 * u * (1 - u) * (1 - 2 * u))


@dataclass(frozen=True)
class Angles:
    """Yaw, pitch, roll (rad) and their time derivatives at a set of times, each of shape (K,)."""

    yaw: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    d_yaw: np.ndarray
    d_pitch: np.ndarray
    d_roll: np.ndarray


class Trajectory:
    """Base: subclasses give angles(t) and position(t); orientation and rates follow."""

    duration: float

    def angles(self, t: np.ndarray) -> Angles:
        raise NotImplementedError

    def position(self, t: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def orientation(self, t: np.ndarray) -> Rotation:
        """Device-to-world rotations at times t."""
        a = self.angles(np.atleast_1d(np.asarray(t, dtype=np.float64)))
        return Rotation.from_euler("YXZ", np.stack([a.yaw, a.pitch, a.roll], axis=-1))

    def angular_velocity(self, t: np.ndarray) -> np.ndarray:
        """Angular velocity in device axes (rad/s), shape (K, 3): what an ideal gyroscope reads."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        a = self.angles(t)
        r_yaw = Rotation.from_euler("Y", a.yaw[:, None])
        r_yaw_pitch = Rotation.from_euler("YX", np.stack([a.yaw, a.pitch], axis=-1))
        omega_world = (a.d_yaw[:, None] * np.array([0.0, 1.0, 0.0])
                       + a.d_pitch[:, None] * r_yaw.apply([1.0, 0.0, 0.0])
                       + a.d_roll[:, None] * r_yaw_pitch.apply([0.0, 0.0, 1.0]))
        return self.orientation(t).inv().apply(omega_world)

    def acceleration(self, t: np.ndarray, h: float = 1e-3) -> np.ndarray:
        """World acceleration (m/s²) by a fourth-order central difference of the smooth position."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        p = [self.position(t + k * h) for k in (-2, -1, 0, 1, 2)]
        return (-p[0] + 16 * p[1] - 30 * p[2] + 16 * p[3] - p[4]) / (12 * h * h)

    def specific_force(self, t: np.ndarray) -> np.ndarray:
        """What an ideal accelerometer reads, in device axes (m/s²): R^T (a - g); +9.81 up at rest."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        return self.orientation(t).inv().apply(self.acceleration(t) - GRAVITY)

    def camera_orientation(self, t: np.ndarray, camera_to_device: Rotation | None = None) -> Rotation:
        """OpenCV-camera-to-world rotations of the back camera (nominal mount unless given)."""
        return self.orientation(t) * (camera_to_device or Rotation.from_matrix(CAMERA_TO_DEVICE))


@dataclass(frozen=True)
class CaptureSweep(Trajectory):
    """A person turning on the spot with the phone held out, sweeping the camera in a spiral from
    `pitch_from_deg` to `pitch_to_deg` over `turns` full turns, easing in and out; the hand adds a
    slow roll wobble and a few centimetres of sway around `origin`."""

    duration: float = 60.0
    turns: float = 5.0
    pitch_from_deg: float = -75.0
    pitch_to_deg: float = 75.0
    roll_wobble_deg: float = 3.0
    sway_m: float = 0.03
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def angles(self, t: np.ndarray) -> Angles:
        u, du, _ = _smoothstep(t / self.duration)
        du = du / self.duration
        pitch_span = np.deg2rad(self.pitch_to_deg - self.pitch_from_deg)
        wobble = np.deg2rad(self.roll_wobble_deg)
        w = 2 * np.pi * 0.25  # a slow roll wobble, 0.25 Hz
        return Angles(
            yaw=2 * np.pi * self.turns * u,
            pitch=np.deg2rad(self.pitch_from_deg) + pitch_span * u,
            roll=wobble * np.sin(w * t),
            d_yaw=2 * np.pi * self.turns * du,
            d_pitch=pitch_span * du,
            d_roll=wobble * w * np.cos(w * t),
        )

    def position(self, t: np.ndarray) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        s = self.sway_m
        sway = np.stack([s * np.sin(2 * np.pi * 0.11 * t), 0.5 * s * np.sin(2 * np.pi * 0.23 * t + 1.0),
                         s * np.cos(2 * np.pi * 0.07 * t)], axis=-1)
        return np.asarray(self.origin) + sway


@dataclass(frozen=True)
class Static(Trajectory):
    """The phone lying still (for noise statistics), screen up by default."""

    duration: float = 60.0
    pitch_deg: float = -90.0

    def angles(self, t: np.ndarray) -> Angles:
        zero = np.zeros_like(np.asarray(t, dtype=np.float64))
        return Angles(zero, zero + np.deg2rad(self.pitch_deg), zero, zero, zero, zero)

    def position(self, t: np.ndarray) -> np.ndarray:
        return np.zeros(np.shape(np.atleast_1d(t)) + (3,))


@dataclass(frozen=True)
class ARPath(Trajectory):
    """Walking around the marker (at the origin, on the table y = 0) while looking at it: the phone
    circles `laps` times at a distance swinging between `near_m` and `far_m`, seen from 27 to 43
    degrees above the table, with a hand shake of about `shake_deg`. In each `look_away` window
    (start, end in seconds) the view swings 70 degrees off the marker and back: the tag is lost."""

    duration: float = 30.0
    laps: float = 1.0
    near_m: float = 0.3
    far_m: float = 1.5
    shake_deg: float = 0.5
    look_away: tuple[tuple[float, float], ...] = ((12.0, 15.0),)

    def position(self, t: np.ndarray) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        u, _, _ = _smoothstep(t / self.duration)
        azimuth = 2 * np.pi * self.laps * u
        mid, amp = (self.far_m + self.near_m) / 2, (self.far_m - self.near_m) / 2
        radius = mid - amp * np.cos(2 * np.pi * t / self.duration * 1.5)  # near, far and near again
        elevation = np.deg2rad(35.0 + 8.0 * np.sin(2 * np.pi * t / 7.0))
        ground = radius * np.cos(elevation)
        return np.stack([ground * np.sin(azimuth), radius * np.sin(elevation), ground * np.cos(azimuth)], axis=-1)

    def _away(self, t: np.ndarray) -> np.ndarray:
        """0 while looking at the marker, rising smoothly to 1 inside each look-away window."""
        out = np.zeros_like(t)
        for start, end in self.look_away:
            ramp = min(1.0, (end - start) / 3)
            up, _, _ = _smoothstep((t - start) / ramp)
            down, _, _ = _smoothstep((end - t) / ramp)
            out = np.maximum(out, np.minimum(up, down))
        return out

    def _look_angles(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Yaw, pitch and roll (rad) of the look direction at times t (K,)."""
        forward = -self.position(t)  # towards the marker
        forward /= np.linalg.norm(forward, axis=-1, keepdims=True)
        yaw = np.arctan2(-forward[:, 0], -forward[:, 2])
        pitch = np.arcsin(np.clip(forward[:, 1], -1, 1))
        yaw = yaw + np.deg2rad(70.0) * self._away(t)
        shake = np.deg2rad(self.shake_deg)
        yaw = yaw + shake * (0.6 * np.sin(2 * np.pi * 2.3 * t) + 0.4 * np.sin(2 * np.pi * 4.1 * t + 1.0))
        pitch = pitch + shake * (0.6 * np.sin(2 * np.pi * 3.1 * t + 2.0) + 0.4 * np.sin(2 * np.pi * 5.3 * t))
        roll = shake * np.sin(2 * np.pi * 1.7 * t + 0.5)
        return yaw, pitch, roll

    def angles(self, t: np.ndarray) -> Angles:
        # The look-at angles have no convenient closed-form derivative: a fourth-order central difference
        # of these smooth functions is accurate to about 1e-9 rad/s, far below any gyroscope's noise.
        h = 1e-4
        samples = [self._look_angles(t + k * h) for k in (-2, -1, 0, 1, 2)]

        def derivative(i: int) -> np.ndarray:
            v = [np.unwrap(np.stack([s[i] for s in samples]), axis=0)[k] for k in range(5)]
            return (v[0] - 8 * v[1] + 8 * v[3] - v[4]) / (12 * h)

        yaw, pitch, roll = samples[2]
        return Angles(yaw, pitch, roll, derivative(0), derivative(1), derivative(2))
