"""The online pass's drift correction: a Kalman filter on what the fused orientation is off by, with the
gyroscope's bias and calibration in its state, so that accepted alignments teach it the drift's cause and
the correction keeps following the drift between them (clear sky, dark walls: nothing to match).

State (18,): theta, the fused camera-to-world orientation's error as a world-frame rotation vector
(fused = exp(theta) true); b, the gyroscope's residual bias in camera axes (rad/s); d, its 3x3 scale and
misalignment error D (row-major; the gyroscope reads (I + D) omega + b); a, the accelerometer's bias in
camera axes (m/s²). Between frames the fusion filter integrates the gyroscope's errors into its
orientation, turned into the world by the camera's orientation, while its accelerometer feedback (the
Mahony filter's kp) pulls the tilt part of theta towards the tilt the accelerometer's bias shows:
    theta' = -kp P (theta - R (u x a) / g) + R (b + D omega)
with P the projection on the axes the fusion corrects (the horizontal ones; all three with the
magnetometer), R, omega the camera-to-world orientation and the camera's rate and u = R^T up. (Without
a, the 20 s sweep with a 1 degree/s gyroscope bias is modelled to 0.22 degrees RMS at best; with it, 0.09.) A metered frame's
alignment measures theta directly. The prior, the random walk of b and the white noise come from the
device's own figures (GyroNoise); so does the gate: a measurement further from the prediction than the
filter's uncertainty allows is a false match, and a gyroscope with a 1 degree/s turn-on bias widens the
gate until its drift is learnt instead of rejecting its corrections.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.capture.refine import GyroNoise

ALIGN_SIGMA_DEG = 0.1  # an online alignment's error, per axis (quarter-size SIFT against the probe so far)...
TEXEL_SHARE = 1 / 8  # ...and this share of the probe's texel (an angle map of N texels has 360/N degrees each):
# against a 128² probe (2.8 degrees a texel) the alignments were 2 degrees off the truth
GATE_DEG = 0.5  # a measurement this close to the prediction is always plausible
GATE_SIGMAS = 4.0  # beyond that, one further than this many standard deviations of the prediction is a false match
REACQUIRE = 3  # this many measurements in a row, all gated out but agreeing with each other within GATE_DEG, are
# taken: the filter had locked itself out (its errors extrapolated across a dark stretch). The night sweep's online
# pass: 5.0 degrees RMS without this, 3.7 with it (1.4 with the fixed-gain correction it replaced): once locked
# out, the probe it smears agrees with it. Without D and a in the state: 3.4, but the default sweep 2.7 (0.13).
MODEL_DEG_PER_S = 0.05  # what the model leaves out (the hand's accelerations, the fusion's non-linearity), as a
# white drift rate of the orientation: degrees/s/sqrt(Hz)
STATE = 18
STANDARD_GRAVITY = 9.80665


class DriftFilter:
    """The correction (exp(-theta)) to apply to the fused camera-to-world orientations (K,) at times (K,) s,
    frame by frame: predict(k), then update(measured) where an alignment measured frame k's orientation."""

    def __init__(self, fused: Rotation, times: np.ndarray, gyro: GyroNoise, accel_bias: float, kp: float,
                 corrects_heading: bool, probe_size: int):
        """accel_bias: the accelerometer's bias, standard deviation per axis (m/s²); kp: the fusion's feedback
        (1/s); corrects_heading: the fusion reads the magnetometer; probe_size: N of the N x N angle map the
        alignments match against."""
        self.fused, self.times, self.gyro, self.kp = fused, times, gyro, kp
        self.align_variance = np.radians(ALIGN_SIGMA_DEG) ** 2 + np.radians(360.0 / probe_size * TEXEL_SHARE) ** 2
        self.corrected_axes = np.ones(3) if corrects_heading else np.array([1.0, 0.0, 1.0])  # world +y is up
        # the camera's rate (camera axes) from the fused orientations, for the scale errors' share of the drift
        steps = (fused[:-1].inv() * fused[1:]).as_rotvec() / np.maximum(np.diff(times), 1e-9)[:, None]
        self.omega = np.vstack([steps[:1] if len(steps) else np.zeros((1, 3)), steps])
        self.x = np.zeros(STATE)
        sigma = gyro.calibration_sigma()  # D's nine terms, then b's three
        self.P = np.diag(np.concatenate([np.zeros(3), sigma[9:], sigma[:9], np.full(3, accel_bias)]) ** 2)  # theta = 0
        # at frame 0: the gauge
        self.k = 0
        self.rejected: list[np.ndarray] = []  # the measured theta of the alignments gated out in a row

    def predict(self, k: int) -> None:
        """Carry the state from the last frame to frame k (k increasing)."""
        for j in range(self.k + 1, k + 1):
            dt = self.times[j] - self.times[j - 1]
            damp = np.exp(-self.kp * self.corrected_axes * dt)
            rotation = self.fused[j - 1].as_matrix()
            r = rotation * np.sqrt(damp)[:, None]  # the errors integrated, damped half the step
            f = np.eye(STATE)
            f[:3, :3] = np.diag(damp)
            f[:3, 3:6] = r * dt
            f[:3, 6:15] = np.kron(r, self.omega[j]) * dt  # d(R D omega)/d(D row-major)
            u = rotation[1]  # R^T up: world +y in camera axes
            cross = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
            f[:3, 15:] = (self.kp * self.corrected_axes * np.sqrt(damp))[:, None] * (rotation @ cross) / STANDARD_GRAVITY * dt
            q = np.zeros(STATE)
            q[:3] = (self.gyro.noise_density**2 + np.radians(MODEL_DEG_PER_S) ** 2) * dt
            q[3:6] = self.gyro.random_walk**2 * dt
            self.x = f @ self.x
            self.P = f @ self.P @ f.T + np.diag(q)
        self.k = max(self.k, k)

    def correction(self) -> Rotation:
        """The world-frame rotation taking the fused orientation to the filter's estimate: exp(-theta)."""
        return Rotation.from_rotvec(-self.x[:3])

    def gate_rad(self) -> float:
        """How far from the prediction a measurement may be (rad) and still be taken."""
        return float(np.radians(GATE_DEG) + GATE_SIGMAS * np.sqrt(np.linalg.eigvalsh(self.P[:3, :3])[-1]))

    def update(self, measured: Rotation) -> bool:
        """Take an alignment's camera-to-world orientation of the current frame; False (nothing changed) where
        it is further from the prediction than the gate."""
        theta = (self.fused[self.k] * measured.inv()).as_rotvec()
        innovation = theta - self.x[:3]
        if np.linalg.norm(innovation) > self.gate_rad():
            self.rejected.append(theta)
            agreeing = len(self.rejected) >= REACQUIRE and all(
                np.linalg.norm(t - theta) <= np.radians(GATE_DEG) for t in self.rejected[-REACQUIRE:])
            if not agreeing:
                return False
            self.P[:3, :3] += np.outer(innovation, innovation)  # the estimate was that far off: say so
        self.rejected = []
        s = self.P[:3, :3] + np.eye(3) * self.align_variance
        gain = np.linalg.solve(s, self.P[:3, :]).T  # P H^T S^-1, with H picking theta
        self.x = self.x + gain @ innovation
        joseph = np.eye(STATE)
        joseph[:, :3] -= gain
        self.P = joseph @ self.P @ joseph.T + gain @ gain.T * self.align_variance
        return True

    @property
    def bias(self) -> tuple[np.ndarray, np.ndarray]:
        """The gyroscope's residual bias as estimated (camera axes, rad/s) and its standard deviations."""
        return self.x[3:6].copy(), np.sqrt(np.diag(self.P)[3:6])
