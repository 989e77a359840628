"""Global rotation refinement, as panorama stitchers do it (OpenCV's BundleAdjusterRay minimises the same
ray distances): keyframes along the sweep, features matched between every pair of keyframes whose views
overlap (the neighbouring turns of the spiral as well as the next keyframe: loop closures), each pair's
relative rotation from its matched bearings (RANSAC, then Kabsch on the inliers), the gyroscope's
relative rotations between consecutive keyframes as priors weighted by the device's noise figures, and
one robust least-squares over all keyframe orientations (SciPy's `least_squares`, soft-L1 then Cauchy
loss: a false loop closure costs little). The first keyframe holds the gauge (the IMU's orientation there, as the
online pass starts from).

Between keyframes, the correction (refined times the IMU's inverse, a world-frame rotation that the
gyroscope's drift changes slowly) is interpolated in time; each frame's refined orientation is that
correction times the IMU's orientation of the frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation, Slerp

from arsim.capture.align import INLIER_DEG, MIN_INLIERS, robust_rotation, scaled_camera
from arsim.core.conventions import CameraIntrinsics

KEY_DEG = 5.0  # a metered frame becomes a keyframe once the view has turned this far from the last one
PAIR_OVERLAP = 0.6  # keyframes are matched when their optical axes are within this fraction of the hfov
MAX_PAIRS = 6  # per keyframe, the nearest in angle taken close in time, and as many taken apart
LOOP_S = 3.0  # keyframes taken further apart than this in time are loop-closure candidates
MIN_PAIR_INLIERS = 12  # a loop closure needs this many agreeing matches
PAIR_FLOOR_DEG = 0.05  # a pair's rotation is known no better than this (measured: 0.05-0.08 degrees median error)
PAIR_GATE_DEG = 1.0  # a pair disagreeing with the online pass's relative rotation by more is a false match
ONLINE_SIGMA_DEG = 0.3  # the online pass's orientations, as priors (its RMS error on the default sweep)
LOSS_SCALE = 3.0  # residuals (in standard deviations) beyond which the Cauchy loss stops trusting a constraint


@dataclass(frozen=True)
class GyroNoise:
    """The figures of the device's gyroscope that bound how far its integrated rotation can be off."""

    noise_density: float  # rad/s/sqrt(Hz)
    bias: float  # rad/s: the turn-on bias and the bias instability together
    scale_factor: float  # relative

    @classmethod
    def of(cls, gyroscope) -> GyroNoise:
        """From a scenario's [device.gyroscope] section."""
        return cls(gyroscope.noise_density, gyroscope.turn_on_bias + gyroscope.bias_instability, gyroscope.scale_factor)

    def sigma(self, dt: float, angle: float) -> float:
        """Standard deviation (rad, per axis) of the integrated relative rotation over dt seconds in which the
        device turned by angle radians."""
        return float(np.sqrt(self.noise_density**2 * dt + (self.bias * dt) ** 2 + (self.scale_factor * angle) ** 2
                             + np.radians(0.01) ** 2))  # (a floor: the fusion's own interpolation)


@dataclass
class Keyframe:
    frame: int  # index into the recording's frames
    bearings: np.ndarray  # (n, 3) unit vectors in camera axes of the features
    descriptors: np.ndarray | None  # (n, 128) float32 SIFT


@dataclass
class Refinement:
    """What the refinement did: the keyframes, the constraints, and the frames' refined orientations."""

    orientations: Rotation  # refined camera-to-world per frame
    keyframes: np.ndarray  # (M,) frame indices
    loop_closures: int  # feature pairs used, consecutive keyframes included
    pairs_tried: int
    cost_before: float
    cost_after: float


class KeyframeFeatures:
    """SIFT on each keyframe at a quarter of the frame's size (what the online aligner sees), contrast
    equalised first; bearings unprojected through the camera."""

    def __init__(self, camera: CameraIntrinsics, scale: float = 0.25):
        self.camera = scaled_camera(camera, scale)
        self.sift = cv2.SIFT_create(nfeatures=800, contrastThreshold=0.01)
        self.clahe = cv2.createCLAHE(clipLimit=6.0, tileGridSize=(4, 4))

    def small(self, codes: np.ndarray) -> np.ndarray:
        """The frame at the size features are found at (what to keep of a frame that may become a keyframe)."""
        return cv2.resize(codes, (self.camera.width, self.camera.height), interpolation=cv2.INTER_AREA)

    def __call__(self, frame: int, codes: np.ndarray) -> Keyframe:
        small = codes if codes.shape[:2] == (self.camera.height, self.camera.width) else self.small(codes)
        grey = self.clahe.apply(cv2.cvtColor(small, cv2.COLOR_RGB2GRAY))
        # (clipped and black regions have no texture of the scene: no mask needed, SIFT finds none there)
        keypoints, descriptors = self.sift.detectAndCompute(grey, None)
        points = np.array([k.pt for k in keypoints], dtype=np.float64).reshape(-1, 2)
        return Keyframe(frame, self.camera.unproject(points), descriptors)


def match_pair(a: Keyframe, b: Keyframe, rng: np.random.Generator) -> tuple[Rotation, float, int] | None:
    """The relative rotation Q with bearings_a ≈ Q bearings_b (so Q = R_a⁻¹ R_b for camera-to-world R),
    its standard deviation per axis (rad) and its inlier count; None without a reliable match."""
    if a.descriptors is None or b.descriptors is None or len(a.bearings) < MIN_INLIERS or len(b.bearings) < MIN_INLIERS:
        return None
    matches = cv2.BFMatcher(cv2.NORM_L2, crossCheck=True).match(a.descriptors, b.descriptors)
    if len(matches) < MIN_PAIR_INLIERS:
        return None
    ba = a.bearings[[m.queryIdx for m in matches]]
    bb = b.bearings[[m.trainIdx for m in matches]]
    q, inliers = robust_rotation(ba, bb, rng)
    n = int(inliers.sum())
    if q is None or n < MIN_PAIR_INLIERS:
        return None
    residual = np.arccos(np.clip(np.einsum("kj,kj->k", ba[inliers], bb[inliers] @ q.T), -1.0, 1.0))
    # the rotation's uncertainty: the bearings' scatter over the root of their count (a floor of a tenth of
    # the inlier angle: a few perfectly agreeing matches do not pin a rotation to nothing)
    spread = float(np.sqrt(np.mean(residual**2)))
    return Rotation.from_matrix(q), max(spread / np.sqrt(n), np.radians(PAIR_FLOOR_DEG)), n


def select_keyframes(metered: np.ndarray, orientations: Rotation) -> np.ndarray:
    """Metered frames (indices, in order) taken as keyframes: the first, then each one that has turned
    KEY_DEG from the last keyframe."""
    keys = [int(metered[0])]
    axes = orientations.apply([0.0, 0.0, 1.0])
    for k in metered[1:]:
        if np.degrees(np.arccos(np.clip(axes[k] @ axes[keys[-1]], -1, 1))) >= KEY_DEG:
            keys.append(int(k))
    return np.array(keys)


def candidate_pairs(keys: np.ndarray, times: np.ndarray, orientations: Rotation, hfov_deg: float) -> list[tuple[int, int]]:
    """Index pairs (i < j) of keyframes to match: consecutive ones; for each keyframe the MAX_PAIRS nearest in
    viewing direction among those within PAIR_OVERLAP of the field of view taken within LOOP_S of it; and as
    many among those taken longer before or after (the spiral's other turns: the loop closures, which a
    nearest-only choice would crowd out with the keyframe's own neighbours)."""
    axes = orientations[keys].apply([0.0, 0.0, 1.0])
    angles = np.degrees(np.arccos(np.clip(axes @ axes.T, -1.0, 1.0)))
    t = times[keys]
    pairs = {(i, i + 1) for i in range(len(keys) - 1)}
    for i in range(len(keys)):
        near = np.abs(t - t[i]) <= LOOP_S
        for group in (near, ~near):
            order = [j for j in np.argsort(angles[i]) if j != i and group[j] and angles[i, j] < PAIR_OVERLAP * hfov_deg]
            pairs.update((min(i, int(j)), max(i, int(j))) for j in order[:MAX_PAIRS])
    return sorted(pairs)


def _residuals(x, initial, ii, jj, q_inv, inv_sigma, prior_inv, prior_inv_sigma):
    """Per constraint (i, j, Q): rotvec(Q⁻¹ R_i⁻¹ R_j) / sigma, with R_k = exp(x_k) R⁰_k (x_0 = 0); then per
    keyframe its prior: rotvec(P_k⁻¹ R_k) / sigma_P."""
    rot = Rotation.from_rotvec(np.vstack([np.zeros(3), x.reshape(-1, 3)])) * initial
    relative = (q_inv * rot[ii].inv() * rot[jj]).as_rotvec() * inv_sigma[:, None]
    absolute = (prior_inv * rot).as_rotvec() * prior_inv_sigma[:, None]
    return np.concatenate([relative.ravel(), absolute.ravel()])


def solve(initial: Rotation, constraints: list[tuple[int, int, Rotation, float]], prior: Rotation | None = None,
          prior_sigma: np.ndarray | None = None) -> tuple[Rotation, float, float]:
    """The keyframe orientations minimising the robust sum over constraints (i, j, Q, sigma) of
    |rotvec(Q⁻¹ R_i⁻¹ R_j)|² / sigma² and over keyframes of |rotvec(P_k⁻¹ R_k)|² / sigma_k² (prior P, where
    given; sigma inf: none), keyframe 0 held; with the cost before and after."""
    m = len(initial)
    if m < 2:
        return initial, 0.0, 0.0
    ii = np.array([c[0] for c in constraints])
    jj = np.array([c[1] for c in constraints])
    q_inv = Rotation.concatenate([c[2] for c in constraints]).inv()
    inv_sigma = 1.0 / np.array([c[3] for c in constraints])
    prior = initial if prior is None else prior
    prior_inv_sigma = np.zeros(m) if prior_sigma is None else 1.0 / np.asarray(prior_sigma, dtype=np.float64)
    args = (initial, ii, jj, q_inv, inv_sigma, prior.inv(), prior_inv_sigma)
    sparsity = lil_matrix((3 * len(constraints) + 3 * m, 3 * (m - 1)), dtype=np.int8)
    for r, (i, j) in enumerate(zip(ii, jj)):
        for k in (i, j):
            if k > 0:
                sparsity[3 * r:3 * r + 3, 3 * (k - 1):3 * k] = 1
    for k in range(1, m):
        r = len(constraints) + k
        sparsity[3 * r:3 * r + 3, 3 * (k - 1):3 * k] = 1
    x0 = np.zeros(3 * (m - 1))
    # Soft-L1 first (convex enough to pull a drifted start in), then Cauchy from there: its influence falls
    # off with the residual, so a false loop closure is all but ignored (started far off, it would stall).
    result = least_squares(_residuals, x0, args=args, jac_sparsity=sparsity, loss="soft_l1", f_scale=LOSS_SCALE,
                           x_scale="jac", method="trf", max_nfev=50)
    result = least_squares(_residuals, result.x, args=args, jac_sparsity=sparsity, loss="cauchy", f_scale=LOSS_SCALE,
                           x_scale="jac", method="trf", max_nfev=50)
    before = float(np.sum(_residuals(x0, *args) ** 2))
    refined = Rotation.from_rotvec(np.vstack([np.zeros(3), result.x.reshape(-1, 3)])) * initial
    return refined, before, float(np.sum(result.fun**2))


def interpolate(times: np.ndarray, keys: np.ndarray, refined_keys: Rotation, imu: Rotation) -> Rotation:
    """Every frame's orientation: the correction (refined times the IMU's inverse) at the keyframes, slerped
    over time (held beyond the first and last), times the frame's IMU orientation."""
    corrections = refined_keys * imu[keys].inv()
    if len(keys) == 1:
        return Rotation.concatenate([corrections] * len(times)) * imu
    t = np.clip(times, times[keys[0]], times[keys[-1]])
    return Slerp(times[keys], corrections)(t) * imu


def refine(times: np.ndarray, metered: np.ndarray, imu: Rotation, online: Rotation, frames, hfov_deg: float,
           camera: CameraIntrinsics, gyro: GyroNoise, seed: int = 0) -> Refinement:
    """Refined orientations of every frame. times (K,): seconds; metered: indices of the frames taken at the
    metered exposure (the ones matched); imu: the IMU's camera-to-world orientations (K,); online: the
    online pass's (candidate pairs and the initial values); frames(k): frame k's 8-bit codes."""
    keys = select_keyframes(metered, online)
    features = KeyframeFeatures(camera)  # (frames(k) may give the frame at features.small's size already)
    keyframes = [features(int(k), frames(int(k))) for k in keys]
    rng = np.random.default_rng(seed)
    constraints: list[tuple[int, int, Rotation, float]] = []
    # The gyroscope's relative rotation between consecutive keyframes: always there, featureless or not.
    for i in range(len(keys) - 1):
        q = imu[keys[i]].inv() * imu[keys[i + 1]]
        constraints.append((i, i + 1, q, gyro.sigma(times[keys[i + 1]] - times[keys[i]], q.magnitude())))
    pairs = candidate_pairs(keys, times, online, hfov_deg)
    used = 0
    for i, j in pairs:
        found = match_pair(keyframes[i], keyframes[j], rng)
        if found is not None and np.degrees((found[0].inv() * online[keys[i]].inv() * online[keys[j]]).magnitude()) < PAIR_GATE_DEG:
            constraints.append((i, j, found[0], found[1]))
            used += 1
    # Start from the online orientations moved so that keyframe 0 is the IMU's (the gauge).
    start = imu[keys[0]] * online[keys[0]].inv() * online[keys]
    # The online pass's orientations as weak priors: where keyframes share no features (a blank ceiling) the
    # online alignment against the whole probe so far still held them.
    refined_keys, before, after = solve(start, constraints, start, np.full(len(keys), np.radians(ONLINE_SIGMA_DEG)))
    return Refinement(interpolate(times, keys, refined_keys, imu), keys, used, len(pairs), before, after)
