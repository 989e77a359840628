"""Tag poses fused with the IMU (README: AR session, Tracking): an error-state Kalman filter on the device's
pose (rotation, position, velocity, gyroscope and accelerometer biases: 15 error states), propagated
with the gyroscope and the accelerometer between frames and corrected by each frame's tag pose.

The tag's measurement is taken as what its corners determine well: the camera's rotation, and the tag's
centre in the camera's frame, whose direction the image pins to a few hundredths of a pixel and whose
depth the tag's apparent size pins less well. The camera's position then comes from the fused rotation
(smoothed by the gyroscope, which knows how the phone turned between frames) rather than from the
rotation of one frame, whose error swings the position round the tag by distance x angle.

Measurement noise follows from the detector's corner noise (tracking/detectors.py: CORNER_SIGMA_PX) and
the tag's size on the screen; process noise from the IMU's datasheet figures (the scenario's device
section) with the errors the filter does not model (scale factors, misalignment) as extra noise. When
the tag is lost the pose is extrapolated from the IMU while its predicted uncertainty stays within the
trust limits (TRUST_ROTATION_DEG, TRUST_POSITION_PCT of the distance); past them, nothing is drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

GRAVITY = np.array([0.0, -9.80665, 0.0])  # world +y up (README: Conventions)
TRUST_ROTATION_DEG = 0.5  # an extrapolated pose is drawn while its rotation's 1-sigma stays under this
TRUST_POSITION_PCT = 1.0  # ... and its position's under this percent of the distance to the tag
GATE_CHI2 = 40.0  # a tag pose further than this (Mahalanobis, 6 dof) from the prediction is not taken
RESET_AFTER = 3  # tag poses refused in a row before the filter starts again from the tag


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _exp(v: np.ndarray) -> np.ndarray:
    return Rotation.from_rotvec(v).as_matrix()


def _log(r: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(r).as_rotvec()


@dataclass(frozen=True)
class ImuNoise:
    """Continuous-time noise densities: gyroscope (rad/s/sqrt(Hz)) and its bias walk (rad/s/sqrt(s)),
    accelerometer (m/s^2/sqrt(Hz)) and its bias walk; initial bias sigmas (rad/s, m/s^2); the share of a
    reading the filter leaves unmodelled (scale factor and misalignment)."""

    gyro: float
    gyro_walk: float
    accel: float
    accel_walk: float
    gyro_bias: float
    accel_bias: float
    gyro_unmodelled: float
    accel_unmodelled: float

    @classmethod
    def of(cls, gyroscope, accelerometer) -> ImuNoise:
        """From a scenario's [device.gyroscope] and [device.accelerometer] sections (the datasheet)."""
        # (bias instability drifts the bias too: taken as part of its walk over the correlation time)
        return cls(gyroscope.noise_density,
                   gyroscope.bias_random_walk + gyroscope.bias_instability / np.sqrt(gyroscope.bias_correlation_s),
                   accelerometer.noise_density,
                   accelerometer.bias_random_walk + accelerometer.bias_instability / np.sqrt(accelerometer.bias_correlation_s),
                   max(3 * gyroscope.turn_on_bias, 1e-4), max(3 * accelerometer.turn_on_bias, 1e-2),
                   gyroscope.scale_factor + gyroscope.misalignment_rad, accelerometer.scale_factor + accelerometer.misalignment_rad)


@dataclass
class FusedPose:
    """The filter's camera pose at a frame: camera-to-world rotation and position, whether it is
    extrapolated (no tag pose taken in this frame), for how long (s), and its 1-sigma rotation (deg) and
    position (m)."""

    camera_to_world: np.ndarray
    position: np.ndarray
    extrapolated: bool
    since_tag_s: float
    sigma_rotation_deg: float
    sigma_position_m: float


class PoseFilter:
    """The error-state Kalman filter. The device's pose is the state (camera = device turned by the mount,
    at the same point); predict() integrates the IMU up to a time, update() takes a tag pose."""

    def __init__(self, camera_to_device: np.ndarray, noise: ImuNoise):
        self.mount = np.asarray(camera_to_device, dtype=np.float64)  # v_device = mount @ v_camera
        self.noise = noise
        self.t_ns: int | None = None  # None: not started (no tag seen yet)
        self.refused = 0
        self.last_tag_ns: int | None = None

    # -- state ---------------------------------------------------------------------------------------

    def start(self, t_ns: int, camera_to_world: np.ndarray, position: np.ndarray) -> None:
        self.R = camera_to_world @ self.mount.T  # device to world
        self.p, self.v = np.asarray(position, dtype=np.float64).copy(), np.zeros(3)
        self.bg, self.ba = np.zeros(3), np.zeros(3)
        self.P = np.diag(np.concatenate([np.full(3, np.radians(2.0) ** 2), np.full(3, 0.05 ** 2), np.full(3, 0.5 ** 2),
                                         np.full(3, self.noise.gyro_bias ** 2), np.full(3, self.noise.accel_bias ** 2)]))
        self.t_ns = self.last_tag_ns = int(t_ns)
        self.refused, self.turned_since_tag = 0, 0.0
        self._last_w, self._last_a = np.zeros(3), -self.R.T @ GRAVITY  # (at rest, until a sample comes)

    @property
    def started(self) -> bool:
        return self.t_ns is not None

    def camera_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.R @ self.mount, self.p

    # -- prediction ----------------------------------------------------------------------------------

    def predict(self, t_ns: int, gyro_t: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> None:
        """Integrate the IMU samples (device axes; accel interpolated to the gyroscope's times) from the
        filter's time up to t_ns."""
        if not self.started or t_ns <= self.t_ns:
            return
        inside = (gyro_t > self.t_ns) & (gyro_t <= t_ns)
        times = np.concatenate([[self.t_ns], gyro_t[inside], [t_ns]]).astype(np.float64)
        w_samples, a_samples = gyro[inside], accel[inside]
        # each step uses the sample at its end (the last step, to t_ns, the last sample seen)
        last_w = w_samples[-1] if len(w_samples) else self._last_w
        last_a = a_samples[-1] if len(a_samples) else self._last_a
        ws = np.vstack([w_samples, last_w[None]]) if len(w_samples) else last_w[None]
        accs = np.vstack([a_samples, last_a[None]]) if len(a_samples) else last_a[None]
        n = self.noise
        turned = 0.0  # the angle turned (rad): the gyroscope's scale and axis errors grow with it, not with time
        for dt_ns, w, a in zip(np.diff(times), ws, accs):
            dt = dt_ns * 1e-9
            if dt <= 0:
                continue
            omega, f = w - self.bg, a - self.ba
            acc_world = self.R @ f + GRAVITY
            F = np.eye(15)
            F[0:3, 0:3] = _exp(-omega * dt)
            F[0:3, 9:12] = -np.eye(3) * dt
            F[3:6, 6:9] = np.eye(3) * dt
            F[6:9, 0:3] = -self.R @ _skew(f) * dt
            F[6:9, 12:15] = -self.R * dt
            turned += np.linalg.norm(omega) * dt
            gyro_var = n.gyro ** 2
            accel_var = n.accel ** 2 + (n.accel_unmodelled * np.linalg.norm(a)) ** 2 * dt
            Q = np.zeros(15)
            Q[0:3], Q[6:9] = gyro_var * dt, accel_var * dt
            Q[9:12], Q[12:15] = n.gyro_walk ** 2 * dt, n.accel_walk ** 2 * dt
            self.p = self.p + self.v * dt + 0.5 * acc_world * dt * dt
            self.v = self.v + acc_world * dt
            self.R = self.R @ _exp(omega * dt)
            self.P = F @ self.P @ F.T + np.diag(Q)
        self.P[0:3, 0:3] += (n.gyro_unmodelled * turned) ** 2 * np.eye(3)
        self.turned_since_tag += turned
        self._last_w, self._last_a = last_w, last_a
        self.t_ns = int(t_ns)

    # -- measurement ---------------------------------------------------------------------------------

    def update(self, t_ns: int, camera_to_world: np.ndarray, tag_in_camera: np.ndarray, sigma_rotation: float,
               sigma_lateral: float, sigma_depth: float) -> bool:
        """Take a tag pose: the camera's rotation (world from camera) and the tag's centre in the camera's
        frame, with their 1-sigma errors (rad; m across the line of sight and along it). Returns whether it
        was taken (a pose far from the prediction is refused; RESET_AFTER in a row restart the filter)."""
        t = np.asarray(tag_in_camera, dtype=np.float64)
        if not self.started:
            self.start(t_ns, camera_to_world, -camera_to_world @ t)
            return True
        M = self.mount
        Rc = self.R @ M  # camera to world
        predicted_t = -Rc.T @ self.p
        r_theta = _log(self.R.T @ (camera_to_world @ M.T))  # rotation residual, device frame (right)
        r_t = t - predicted_t
        H = np.zeros((6, 15))
        H[0:3, 0:3] = np.eye(3)
        H[3:6, 0:3] = -M.T @ _skew(self.R.T @ self.p)  # t = -M^T R^T p, R = R^ Exp(dtheta)
        H[3:6, 3:6] = -M.T @ self.R.T
        u = t / max(np.linalg.norm(t), 1e-9)
        Rt = sigma_lateral ** 2 * np.eye(3) + (sigma_depth ** 2 - sigma_lateral ** 2) * np.outer(u, u)
        Rm = np.zeros((6, 6))
        Rm[0:3, 0:3], Rm[3:6, 3:6] = sigma_rotation ** 2 * np.eye(3), Rt
        residual = np.concatenate([r_theta, r_t])
        S = H @ self.P @ H.T + Rm
        if residual @ np.linalg.solve(S, residual) > GATE_CHI2:
            self.refused += 1
            if self.refused >= RESET_AFTER:
                self.start(t_ns, camera_to_world, -camera_to_world @ t)
                return True
            return False
        K = self.P @ H.T @ np.linalg.inv(S)
        dx = K @ residual
        I_KH = np.eye(15) - K @ H
        self.P = I_KH @ self.P @ I_KH.T + K @ Rm @ K.T
        self.R = self.R @ _exp(dx[0:3])
        self.p, self.v = self.p + dx[3:6], self.v + dx[6:9]
        self.bg, self.ba = self.bg + dx[9:12], self.ba + dx[12:15]
        self.refused, self.last_tag_ns, self.turned_since_tag = 0, int(t_ns), 0.0
        return True

    def sigmas(self) -> tuple[float, float]:
        """1-sigma rotation (deg) and position (m) of the current state; the rotation's with the gyroscope's
        unmodelled share of the whole angle turned since the last tag pose (a systematic error grows with it
        in full, where the filter's variance adds it frame by frame)."""
        drift = self.noise.gyro_unmodelled * self.turned_since_tag
        return (float(np.degrees(np.sqrt(np.trace(self.P[0:3, 0:3])) + drift)), float(np.sqrt(np.trace(self.P[3:6, 3:6]))))


# Measurement noise from the corners: sigma_px of each corner (the detector's), the tag's side s (m), the
# focal length f (px) and the distance d: the rotation ROTATION x sigma_px d / (f s), the tag's centre along
# the line of sight DEPTH x sigma_px d^2 / (f s) (its apparent size), across it LATERAL x sigma_px d / f.
# The factors: the RMS of AprilTag 3's and OpenCV's errors in those units on the quick scenario's AR path
# (rotation 1.3 to 1.8 per axis, depth 0.7 to 0.9, lateral 0.4 to 0.8), taken about 1.3 times larger; the
# default and lost_tag paths, on which the filter is measured (benchmarks/bench_tracking.py), played no part.
ROTATION, DEPTH, LATERAL = 2.3, 1.2, 1.0


class FusedTracker:
    """A TagTracker's poses fused with an AR recording's IMU: track(frame, index) for its frames in order
    (frames may be skipped; a frame seen again gives the pose it gave). A frame without the tag (or with a
    pose the filter refuses) gets the extrapolated pose while it is trusted, else LOST."""

    def __init__(self, tracker, frame_times_ns: np.ndarray, imu: dict, camera_to_device: np.ndarray, noise: ImuNoise,
                 corner_sigma_px: float):
        self.tracker, self.times = tracker, np.asarray(frame_times_ns, dtype=np.int64)
        gyro, accel = imu["gyroscope"], imu["accelerometer"]
        self.gyro_t, self.gyro = np.asarray(gyro.t_ns, dtype=np.int64), np.asarray(gyro.values, dtype=np.float64)
        self.accel = np.stack([np.interp(self.gyro_t, accel.t_ns, accel.values[:, i]) for i in range(3)], axis=-1)
        self.filter = PoseFilter(camera_to_device, noise)
        self.sigma_px, self.tag_size = corner_sigma_px, tracker.marker_corners[1, 0] * 2
        self.f = 0.5 * (tracker.camera.fx + tracker.camera.fy)
        self.done: dict[int, object] = {}

    def track(self, frame: np.ndarray, index: int):
        from arsim.tracking.apriltag import LOST, TagPose

        if index in self.done:
            return self.done[index]
        t_ns = int(self.times[index])
        self.filter.predict(t_ns, self.gyro_t, self.gyro, self.accel)
        seen = self.tracker.track(frame)
        taken = False
        if seen.found:
            t = np.asarray(seen.translation, dtype=np.float64)
            d = float(np.linalg.norm(t))
            unit = self.sigma_px / self.f
            taken = self.filter.update(t_ns, seen.rotation.T, t, ROTATION * unit * d / self.tag_size, LATERAL * unit * d,
                                       DEPTH * unit * d * d / self.tag_size)
        if not self.filter.started:
            pose = LOST
        else:
            camera_to_world, position = self.filter.camera_pose()
            since = (t_ns - self.filter.last_tag_ns) * 1e-9
            rot_deg, pos_m = self.filter.sigmas()
            distance = float(np.linalg.norm(position))
            if not taken and (rot_deg > TRUST_ROTATION_DEG or pos_m > TRUST_POSITION_PCT / 100 * distance):
                pose = LOST
            else:
                rotation = camera_to_world.T
                pose = TagPose(rotation, -rotation @ position, seen.corners if taken else None, extrapolated=not taken,
                               since_tag_s=since, sigma_rotation_deg=rot_deg, sigma_position_m=pos_m)
        self.done[index] = pose
        return pose


def recording_tracker(rec, linear_of_code, detector: str, fusion: bool):
    """The tracker of an AR recording's tag (its table's family, id and size, its camera): a TagTracker with
    the detector, fused with the recording's IMU (its scenario's datasheet figures) where fusion is set."""
    from arsim.sensors.frames import recording_camera, recording_scenario
    from arsim.tracking.apriltag import TagTracker
    from arsim.tracking.detectors import CORNER_SIGMA_PX

    table = rec.meta["table"]
    tracker = TagTracker(recording_camera(rec), table["tag_size_m"], table["tag_id"], table["tag_family"], linear_of_code,
                         detector)
    if not fusion:
        return tracker
    device = recording_scenario(rec).device
    times = np.array([f["t_ns"] for f in rec.frames], dtype=np.int64)
    return FusedTracker(tracker, times, rec.imu, rec.meta["camera_to_device"],
                        ImuNoise.of(device.gyroscope, device.accelerometer), CORNER_SIGMA_PX[detector])
