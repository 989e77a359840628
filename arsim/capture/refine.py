"""Global rotation refinement, as panorama stitchers do it (OpenCV's BundleAdjusterRay minimises the same
ray distances): keyframes along the sweep, features matched between every pair of keyframes whose views
overlap (the neighbouring turns of the spiral as well as the next keyframe: loop closures), each pair's
relative rotation from its matched bearings (RANSAC, then Kabsch on the inliers), the gyroscope's
relative rotations between consecutive keyframes as a chain weighted by the device's noise figures, with
the gyroscope's calibration estimated, and one least-squares over all keyframe orientations (SciPy's
`least_squares`; the pairs reweighted soft-L1 then Cauchy: a false loop closure costs little). The first
keyframe holds the gauge (the IMU's orientation there, as the online pass starts from).

Between keyframes, the correction (refined times the IMU's inverse, a world-frame rotation that the
gyroscope's drift changes slowly) is interpolated in time; each frame's refined orientation is that
correction times the IMU's orientation of the frame.
"""

from __future__ import annotations

import itertools
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix
from scipy.spatial.transform import Rotation, Slerp

from arsim.capture.align import MIN_INLIERS, robust_rotation, scaled_camera, sift_detector
from arsim.capture.direct import DirectImage, DirectImages, align_direct_all
from arsim.core.conventions import CameraIntrinsics
from arsim.core.worker import SideWorker, side_worker

KEY_DEG = 5.0  # a metered frame becomes a keyframe once the view has turned this far from the last one
KEY_SCALE = 0.5  # features at this fraction of the frame size (a quarter, as the online aligner: pairs' median error
# 0.04-0.08 degrees against 0.03-0.06 at half, and the studio's refined orientation 0.38 -> 0.21, the dim night's
# 1.00 -> 0.65, at twice the refinement's time)
KEY_S = 1.0  # or once this long has passed (the gyroscope's drift between keyframes stays small)
PAIR_OVERLAP = 0.6  # keyframes are matched when their optical axes are within this fraction of the hfov
MAX_PAIRS = 6  # per keyframe, the nearest in angle taken close in time, and as many taken apart
LOOP_S = 3.0  # keyframes taken further apart than this in time are loop-closure candidates
MIN_PAIR_INLIERS = 12  # a loop closure needs this many agreeing matches
PAIR_FLOOR_DEG = 0.05  # added on every axis: a pair's rotation is known no better (measured: 0.05-0.08 degrees median error)
PROGRESS_S = 0.5  # how often the keyframes' features report their progress
# A worker process (arsim.core.worker) takes the pairs' guided matching ahead of this thread's RANSAC, and half
# the direct alignments, GIL-bound (SciPy's least-squares loop); started with the refinement where it has this many
# keyframes (a sweep's worth: the default sweep has 299): fewer hold too little work to pay for starting a process.
SIDE_KEYFRAMES = 100
DIRECT_SHARE = 8  # alignments per share (about 0.1 s of work: the two processes end within one share of each other)
MATCH_SHARE = 32  # pairs per share of guided matching (about 25 ms of work)
# The refinement's progress, by phase: the share of its time each took on the default sweep (keyframe features,
# the calibration's pairs, then each round's pairs and solve)
PHASE_SHARES = (0.3, 0.2, 0.35, 0.15)  # (2 + ROUNDS of them)
PAIR_GATE_DEG = 1.0  # a pair disagreeing with the estimate's relative rotation by more (and the gyroscope's
# possible drift between the two) is a false match; its features are matched within the same (0.3 for the pairs
# taken close in time: the dim studio 0.30, but the night 0.09 -> 0.14, the second seed's night 0.18 -> 0.41)
ROUNDS = 2
CHAIN_FLOOR_DEG = 0.003  # the calibrated chain's error floor (the interpolation between samples; measured: 0.002-0.004
# median with the best calibration; 0.01 let the solve trade the chain for the pairs: 20 s sweep 0.23 -> 0.13 deg)
IRLS_ROUNDS = (2, 3)  # reweighted solves with the soft-L1 weights, then with Cauchy's
LOSS_SCALE = 3.0  # residuals (in standard deviations) beyond which the Cauchy loss stops trusting a constraint


@dataclass(frozen=True)
class GyroNoise:
    """The figures of the device's gyroscope that bound how far its integrated rotation can be off."""

    noise_density: float  # rad/s/sqrt(Hz)
    bias: float  # rad/s: the turn-on bias and the bias instability together
    scale_factor: float  # relative
    misalignment: float = 0.0  # rad: each cross-axis term
    random_walk: float = 0.0  # rad/s/sqrt(s): how fast the bias wanders (its random walk and instability together)

    @classmethod
    def of(cls, gyroscope) -> GyroNoise:
        """From a scenario's [device.gyroscope] section."""
        wander = np.sqrt(gyroscope.bias_random_walk**2 + 2 * gyroscope.bias_instability**2 / gyroscope.bias_correlation_s)
        return cls(gyroscope.noise_density, gyroscope.turn_on_bias + gyroscope.bias_instability, gyroscope.scale_factor,
                   gyroscope.misalignment_rad, float(wander))

    def calibration_sigma(self) -> np.ndarray:
        """The calibration's prior standard deviations (CALIBRATION,): D's diagonal the scale factors, its
        other terms the misalignments, b the bias."""
        d = np.where(np.eye(3, dtype=bool), self.scale_factor, self.misalignment).ravel()
        return np.concatenate([np.maximum(d, 1e-4), np.full(3, max(self.bias, 1e-5))])

    def sigma(self, dt: float, angle: float, calibrated: bool = False) -> float:
        """Standard deviation (rad, per axis) of the integrated relative rotation over dt seconds in which the
        device turned by angle radians; calibrated: with the scale factors and the bias estimated (the
        noise and a tenth of the bias left)."""
        bias, scale = (0.1 * self.bias, 0.0) if calibrated else (self.bias, self.scale_factor)
        return float(np.sqrt(self.noise_density**2 * dt + (bias * dt) ** 2 + (scale * angle) ** 2
                             + np.radians(CHAIN_FLOOR_DEG) ** 2))


def _prefix_products(steps: Rotation) -> Rotation:
    """C_k = s_0 s_1 ... s_k for every k: a Hillis-Steele scan (log2 K vectorised products; rotations
    compose associatively, the earlier prefix on the left), on the quaternions themselves: Rotation's
    products and slices cost 0.2 s a scan of a minute's gyroscope, these a few milliseconds."""
    q = steps.as_quat()  # (x, y, z, w)
    shift = 1
    while shift < len(q):
        a, b = q[:-shift], q[shift:]
        product = np.empty_like(b)
        product[:, :3] = a[:, 3:] * b[:, :3] + b[:, 3:] * a[:, :3] + np.cross(a[:, :3], b[:, :3])
        product[:, 3] = a[:, 3] * b[:, 3] - np.einsum("ij,ij->i", a[:, :3], b[:, :3])
        product /= np.linalg.norm(product, axis=1, keepdims=True)  # (as Rotation's products keep them unit)
        q = np.concatenate([q[:shift], product])
        shift *= 2
    return Rotation.from_quat(q)


def chain_turns(steps: Rotation) -> Rotation:
    """Each keyframe's rotation from the first (M,), from the relative rotations between consecutive ones (M-1,)."""
    return Rotation.concatenate([Rotation.identity(1), _prefix_products(steps)])


def integrated_gyroscope(t_ns: np.ndarray, omega: np.ndarray, times_s: np.ndarray) -> Rotation:
    """The device's rotation since the stream's start at each of times_s, the raw gyroscope (rad/s, device
    axes) integrated sample by sample (each reading held over the interval it ends, as the fusion does),
    slerped between samples. No accelerometer in it: the fused orientation's gravity corrections are
    pulled by the device's sway."""
    dt = np.diff(t_ns.astype(np.float64), prepend=float(t_ns[0])) * 1e-9
    cumulative = _prefix_products(Rotation.from_rotvec(omega * dt[:, None]))
    t = np.clip(times_s * 1e9, float(t_ns[0]), float(t_ns[-1]))
    return Slerp(t_ns.astype(np.float64), cumulative)(t)


CALIBRATION = 12  # the gyroscope's corrections the refinement estimates: omega' = (I + D) omega - b, D 3x3, b (3,)
_STEP = 1e-5  # the finite difference of the relative rotations' Jacobians in them


@dataclass
class GyroIntervals:
    """The raw gyroscope's relative rotations of the camera between consecutive keyframes, and how they
    change with the calibration (linear: D and b are thousandths)."""

    rotations: Rotation  # (M-1,) Q_i = C(t_i)⁻¹ C(t_i+1), camera axes
    jacobians: np.ndarray  # (M-1, 3, CALIBRATION): d rotvec(Q_i⁻¹ Q_i(theta)) / d theta

    @classmethod
    def of(cls, t_ns: np.ndarray, omega: np.ndarray, key_times_s: np.ndarray, mount: Rotation) -> GyroIntervals:
        def relative(w):
            turns = mount.inv() * integrated_gyroscope(t_ns, w, key_times_s) * mount
            return turns[:-1].inv() * turns[1:]

        base = relative(omega)
        jacobians = np.empty((len(base), 3, CALIBRATION))
        for p in range(CALIBRATION):
            if p < 9:
                d = np.zeros((3, 3))
                d.flat[p] = _STEP
                w = omega + omega @ d.T
            else:
                w = omega.copy()
                w[:, p - 9] -= _STEP
            jacobians[:, :, p] = (base.inv() * relative(w)).as_rotvec() / _STEP
        return cls(base, jacobians)

    def at(self, theta: np.ndarray) -> Rotation:
        """The relative rotations with the calibration theta (CALIBRATION,) applied."""
        return self.rotations * Rotation.from_rotvec(self.jacobians @ theta)


@dataclass
class Keyframe:
    frame: int  # index into the recording's frames
    bearings: np.ndarray  # (n, 3) unit vectors in camera axes of the features
    descriptors: np.ndarray | None  # (n, 128) float32 SIFT
    image: DirectImage | None = None  # for direct alignment, where the features pin too little


@dataclass
class Refinement:
    """What the refinement did: the keyframes, the constraints, and the frames' refined orientations."""

    orientations: Rotation  # refined camera-to-world per frame
    keyframes: np.ndarray  # (M,) frame indices
    loop_closures: int  # feature pairs used, consecutive keyframes included
    pairs_tried: int
    cost_before: float
    cost_after: float
    calibration: np.ndarray  # (CALIBRATION,) the gyroscope's estimated corrections (zeros without its stream)
    direct_pairs: int = 0  # of the pairs used, those aligned directly (no feature pair reached their keyframes)
    seconds: float = 0.0  # features, matching and the solve (not the accumulation again)


class KeyframeFeatures:
    """SIFT on each keyframe at KEY_SCALE of the frame's size, contrast
    equalised first; bearings unprojected through the camera."""

    def __init__(self, camera: CameraIntrinsics):
        self.camera = scaled_camera(camera, KEY_SCALE)
        self.sift = sift_detector()
        self.clahe = cv2.createCLAHE(clipLimit=6.0, tileGridSize=(4, 4))
        self.direct: DirectImages | None = None  # set (by the capture, which knows the response): images kept too

    def small(self, codes: np.ndarray) -> np.ndarray:
        """The frame at the size features are found at (what to keep of a frame that may become a keyframe)."""
        return cv2.resize(codes, (self.camera.width, self.camera.height), interpolation=cv2.INTER_AREA)

    def features(self, small: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(bearings, descriptors) of the SIFT features of a frame at small's size (what does not depend on the
        response: EarlyFeatures finds them before it is known)."""
        grey = self.clahe.apply(cv2.cvtColor(small, cv2.COLOR_RGB2GRAY))
        # (clipped and black regions have no texture of the scene: no mask needed, SIFT finds none there)
        keypoints, descriptors = self.sift.detectAndCompute(grey, None)
        points = np.array([k.pt for k in keypoints], dtype=np.float64).reshape(-1, 2)
        return self.camera.unproject(points), descriptors

    def __call__(self, frame: int, codes: np.ndarray, found: tuple | None = None) -> Keyframe:
        """The keyframe of frame's codes (full size or small's); found: its features() where found before."""
        small = codes if codes.shape[:2] == (self.camera.height, self.camera.width) else self.small(codes)
        bearings, descriptors = found if found is not None else self.features(small)
        return Keyframe(frame, bearings, descriptors, None if self.direct is None else self.direct(small))


class EarlyFeatures:
    """The keyframes' SIFT features found on a thread of its own, in order, while the capture does other work: the
    response's calibration (OpenCV, one core) and the online pass leave part of the second core idle. frames(k):
    frame k's codes. stop() lets the keyframe under way finish and gives what was found; the refinement finds the
    rest (keyframe_features). The same features as found there (the same image, SIFT and CLAHE)."""

    def __init__(self, camera: CameraIntrinsics, keys, frames: Callable[[int], np.ndarray]):  # camera: the frames'
        self.found: dict[int, tuple] = {}
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(camera, [int(k) for k in keys], frames),
                                        name="keyframes_early", daemon=True)
        self._thread.start()

    def _run(self, camera: CameraIntrinsics, keys: list[int], frames) -> None:
        features = KeyframeFeatures(camera)
        for k in keys:
            if self._stopping.is_set():
                return
            try:
                codes = frames(k)
            except Exception:  # (an unreadable frame: the capture reads it again itself, and says what is wrong)
                return
            self.found[k] = features.features(features.small(codes))

    def stop(self) -> dict[int, tuple]:
        self._stopping.set()
        self._thread.join()
        return self.found


def keyframe_features(camera: CameraIntrinsics, direct: DirectImages | None, keys, frames,
                      progress: Callable[[float], None] = lambda fraction: None,
                      found: dict[int, tuple] | None = None) -> list[Keyframe]:
    """KeyframeFeatures of each keyframe (frames(k): its codes), on threads that each keep their own
    detector (OpenCV's SIFT and CLAHE run without the GIL): the default sweep's 299 keyframes took 23 ms
    each one after another, 8 ms on two threads, the same features. found: features already found per frame
    (EarlyFeatures). progress(fraction done) is called from this thread (the workers only append to their lists)."""
    found = found or {}
    workers = max(1, min(4, os.cpu_count() or 1, len(keys)))
    shares: list[list[Keyframe]] = [[] for _ in range(workers)]

    def share(start: int) -> None:
        features = KeyframeFeatures(camera)
        features.direct = direct
        for k in keys[start::workers]:
            shares[start].append(features(int(k), frames(int(k)), found.get(int(k))))

    with ThreadPoolExecutor(workers) as pool:
        pending = {pool.submit(share, start) for start in range(workers)}
        while pending:
            finished, pending = wait(pending, timeout=PROGRESS_S)
            for future in finished:
                future.result()  # (a worker's exception, raised here)
            progress(sum(len(s) for s in shares) / max(len(keys), 1))
    return [shares[i % workers][i // workers] for i in range(len(keys))]


def _nearest(rows: np.ndarray, cols: np.ndarray, d2: np.ndarray, count: int) -> np.ndarray:
    """Per row index (0..count-1) the column of its least d2 among the pairs (rows, cols) given, the lowest
    column among equals (as argmin over a row); -1 for a row without a pair."""
    order = np.lexsort((cols, d2, rows))
    first = np.ones(len(order), dtype=bool)
    first[1:] = rows[order][1:] != rows[order][:-1]
    nearest = np.full(count, -1)
    nearest[rows[order][first]] = cols[order][first]
    return nearest


def guided_matches(a: Keyframe, b: Keyframe, expected: Rotation, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Mutual nearest descriptors (indices into a's and b's features) among the pairs whose bearings the expected
    rotation puts within radius of each other. Only those pairs' distances are computed: a gate of a few degrees
    allows a few in a thousand. SIFT's descriptors hold whole numbers, so |d_a|^2 + |d_b|^2 - 2 d_a.d_b is exact
    in float64 whatever the order of its sums: the same matches as over the full distance matrix."""
    rows, cols = np.nonzero((a.bearings @ expected.apply(b.bearings).T) > np.cos(radius))
    da, db = a.descriptors.astype(np.float64), b.descriptors.astype(np.float64)
    d2 = (np.sum(da**2, axis=1)[rows] + np.sum(db**2, axis=1)[cols]
          - 2 * np.einsum("kj,kj->k", da[rows], db[cols]))
    nearest_b, nearest_a = _nearest(rows, cols, d2, len(da)), _nearest(cols, rows, d2, len(db))
    ia = np.flatnonzero(nearest_b >= 0)
    ia = ia[nearest_a[nearest_b[ia]] == ia]
    return ia, nearest_b[ia]


def _matchable(a: Keyframe, b: Keyframe) -> bool:
    """Both keyframes have features enough to be matched."""
    return not (a.descriptors is None or b.descriptors is None or len(a.bearings) < MIN_INLIERS
                or len(b.bearings) < MIN_INLIERS)


# The keyframes' features a worker process matches pairs of (guided_all), by token: sent to it once per refinement.
_KEPT: dict[int, list[Keyframe]] = {}
_TOKENS = itertools.count()


def keep_features(token: int, bearings: list[np.ndarray], descriptors: list[np.ndarray | None]) -> None:
    """The keyframes' features kept in this process under token (descriptors may come as uint8: SIFT's are
    whole numbers within 0-255, and guided_matches computes with them in float64 either way)."""
    _KEPT[token] = [Keyframe(-1, b, d) for b, d in zip(bearings, descriptors)]


def drop_features(token: int) -> None:
    _KEPT.pop(token, None)


def _compact(descriptors: np.ndarray | None) -> np.ndarray | None:
    """SIFT's descriptors as uint8 where they are whole numbers within 0-255 (a quarter of the bytes to send), as
    they are otherwise."""
    if descriptors is not None and np.array_equal(small := descriptors.astype(np.uint8), descriptors):
        return small
    return descriptors


def guided_all(token: int, jobs: list[tuple[int, int, Rotation, float]]) -> list[tuple[np.ndarray, np.ndarray] | None]:
    """guided_matches of each keyframe pair (i, j, expected, radius) of the features kept under token, in order
    (None where match_pair would not match them): a share of a refinement's pairs for a worker process, while
    the caller runs each pair's RANSAC, in order, on the random stream they share."""
    kept = _KEPT[token]
    return [guided_matches(kept[i], kept[j], expected, radius) if _matchable(kept[i], kept[j]) else None
            for i, j, expected, radius in jobs]


def _warm() -> None:
    """Nothing: a first call that has the worker process import this module while the caller works."""


def match_pair(a: Keyframe, b: Keyframe, rng: np.random.Generator, expected: Rotation | None = None,
               radius: float = np.pi, matches: tuple[np.ndarray, np.ndarray] | None = None
               ) -> tuple[Rotation, np.ndarray, int] | None:
    """The relative rotation Q with bearings_a ≈ Q bearings_b (so Q = R_a⁻¹ R_b for camera-to-world R),
    its covariance (3, 3, rad², b's axes) and its inlier count; None without a reliable match. With an
    expected Q, guided, as structure-from-motion pipelines match under a known motion: a feature of b is
    matched only among a's within radius (rad) of where Q puts it, mutual nearest descriptors. In a dark or
    bare view most of the features are noise, and matched without the prior they pass RANSAC in small
    clusters that pin the rotation poorly (with the covariance below: the dim studio's refined orientation
    1.31 -> 0.11 degrees RMS; Lowe's ratio test instead of the mutual check lost the ceiling's few true
    matches: 20 s drifting sweep 0.18 -> 0.26). matches: guided_matches(a, b, expected, radius) where already
    found (guided_all)."""
    if not _matchable(a, b):
        return None
    if matches is not None:
        ia, ib = matches
    elif expected is None:
        found = cv2.BFMatcher(cv2.NORM_L2, crossCheck=True).match(a.descriptors, b.descriptors)
        ia, ib = [m.queryIdx for m in found], [m.trainIdx for m in found]
    else:
        ia, ib = guided_matches(a, b, expected, radius)
    if len(ia) < MIN_PAIR_INLIERS:
        return None
    ba, bb = a.bearings[ia], b.bearings[ib]
    q, inliers = robust_rotation(ba, bb, rng)
    n = int(inliers.sum())
    if q is None or n < MIN_PAIR_INLIERS:
        return None
    # The rotation's covariance from its matches (axes of b, as the solve's residuals): a bearing's tangential
    # scatter s² per axis (from the residuals, three degrees of freedom fitted) times (Σ (I - b bᵀ))⁻¹, the
    # geometry's: features in a band at the frame's edge, as a loop closure between turns sees them, pin the
    # roll about the band's centre poorly. Plus the floor, on every axis. (Measured on the dim studio against
    # the truth: rᵀ C⁻¹ r has the median of chi-squared's 2.37 (2.4), where the scalar sigma had 9.4.)
    bb_in = bb[inliers]
    residual = np.arccos(np.clip(np.einsum("kj,kj->k", ba[inliers], bb_in @ q.T), -1.0, 1.0))
    scatter = float(np.sum(residual**2)) / max(2 * n - 3, 1)
    information = n * np.eye(3) - bb_in.T @ bb_in
    covariance = scatter * np.linalg.inv(information) + isotropic(np.radians(PAIR_FLOOR_DEG))
    return Rotation.from_matrix(q), covariance, n


def select_keyframes(metered: np.ndarray, orientations: Rotation, times: np.ndarray) -> np.ndarray:
    """Metered frames (indices, in order) taken as keyframes: the first, each one that has turned KEY_DEG
    from the last keyframe (the whole rotation: near the sweep's poles the view turns about its own axis
    while the axis hardly moves), or was taken KEY_S after it, and the last."""
    keys = [int(metered[0])]
    for k in metered[1:]:
        if ((orientations[keys[-1]].inv() * orientations[k]).magnitude() >= np.radians(KEY_DEG)
                or times[k] - times[keys[-1]] >= KEY_S):
            keys.append(int(k))
    if keys[-1] != int(metered[-1]):
        keys.append(int(metered[-1]))
    return np.array(keys)


def candidate_pairs(t: np.ndarray, orientations: Rotation, hfov_deg: float) -> list[tuple[int, int]]:
    """Index pairs (i < j) of keyframes (times t, orientations) to match: consecutive ones; for each keyframe the MAX_PAIRS nearest in
    viewing direction among those within PAIR_OVERLAP of the field of view taken within LOOP_S of it; and as
    many among those taken longer before or after (the spiral's other turns: the loop closures, which a
    nearest-only choice would crowd out with the keyframe's own neighbours)."""
    axes = orientations.apply([0.0, 0.0, 1.0])
    angles = np.degrees(np.arccos(np.clip(axes @ axes.T, -1.0, 1.0)))
    pairs = {(i, i + 1) for i in range(len(t) - 1)}
    for i in range(len(t)):
        near = np.abs(t - t[i]) <= LOOP_S
        for group in (near, ~near):
            order = [j for j in np.argsort(angles[i]) if j != i and group[j] and angles[i, j] < PAIR_OVERLAP * hfov_deg]
            pairs.update((min(i, int(j)), max(i, int(j))) for j in order[:MAX_PAIRS])
    return sorted(pairs)


def whitening(covariance: np.ndarray) -> np.ndarray:
    """W with Wᵀ W = covariance⁻¹ for each (..., 3, 3) covariance: W r is a residual r in standard deviations."""
    return np.linalg.inv(np.linalg.cholesky(covariance))


def isotropic(sigma: float) -> np.ndarray:
    """The covariance (3, 3) of a rotation known to sigma (rad) about every axis."""
    return np.eye(3) * sigma**2


def _residuals(x, initial, ii, jj, q_inv, white, prior_inv, prior_inv_sigma, gyro, gyro_inv_sigma, theta_inv_sigma):
    """Per constraint (i, j, Q): W rotvec(Q⁻¹ R_i⁻¹ R_j) (W its whitening), with R_k = exp(x_k) R⁰_k (x_0 = 0); per keyframe
    its prior, rotvec(P_k⁻¹ R_k) / sigma_P; with gyro (GyroIntervals), per consecutive pair the same for the
    gyroscope's rotation under the calibration theta (x's last CALIBRATION entries), and theta's prior."""
    m = len(initial)
    rot = Rotation.from_rotvec(np.vstack([np.zeros(3), x[:3 * (m - 1)].reshape(-1, 3)])) * initial
    parts = [np.einsum("nab,nb->na", white, (q_inv * rot[ii].inv() * rot[jj]).as_rotvec()).ravel(),
             ((prior_inv * rot).as_rotvec() * prior_inv_sigma[:, None]).ravel()]
    if gyro is not None:
        theta = x[3 * (m - 1):]
        chain = gyro.at(theta).inv() * rot[:-1].inv() * rot[1:]
        parts += [(chain.as_rotvec() * gyro_inv_sigma[:, None]).ravel(), theta * theta_inv_sigma]
    return np.concatenate(parts)


def _jacobian(x, initial, ii, jj, q_inv, white, prior_inv, prior_inv_sigma, gyro, gyro_inv_sigma, theta_inv_sigma):
    """_residuals' Jacobian to first order in the residuals (the log's own Jacobian at a small rotation is the
    identity): a constraint rotvec(A R_j ...) moves by A's matrix times a keyframe's perturbation (world
    axes), by minus it for R_i. Sparse; exact at the solution, so Gauss-Newton converges to the same point."""
    m = len(initial)
    rot = Rotation.from_rotvec(np.vstack([np.zeros(3), x[:3 * (m - 1)].reshape(-1, 3)])) * initial
    rows, cols, vals = [], [], []

    def block(row0, k, matrices, scale):
        """3x3 blocks: residual rows row0 + 3n.. by keyframe k's variables (k = 0 is held: none); scale per
        block, a number or a 3x3 matrix on the left."""
        keep = k > 0
        if not np.any(keep):
            return
        r = (np.asarray(row0)[keep][:, None, None] + np.arange(3)[None, :, None]).repeat(3, axis=2)
        c = (3 * (np.asarray(k)[keep] - 1))[:, None, None] + np.arange(3)[None, None, :].repeat(3, axis=1)
        rows.append(r.ravel())
        cols.append(c.ravel())
        scaled = scale[keep] @ matrices[keep] if scale.ndim == 3 else matrices[keep] * scale[keep][:, None, None]
        vals.append(scaled.ravel())

    n = len(ii)
    if n:
        a = (q_inv * rot[ii].inv()).as_matrix()
        block(3 * np.arange(n), jj, a, white)
        block(3 * np.arange(n), ii, a, -white)
    base = 3 * n
    block(base + 3 * np.arange(m), np.arange(m), prior_inv.as_matrix(), prior_inv_sigma)
    base += 3 * m
    n_vars = 3 * (m - 1)
    if gyro is not None:
        theta = x[3 * (m - 1):]
        a = (gyro.at(theta).inv() * rot[:-1].inv()).as_matrix()
        chain_rows = base + 3 * np.arange(m - 1)
        block(chain_rows, np.arange(1, m), a, gyro_inv_sigma)
        block(chain_rows, np.arange(m - 1), a, -gyro_inv_sigma)
        r = (chain_rows[:, None, None] + np.arange(3)[None, :, None]).repeat(CALIBRATION, axis=2)
        c = np.broadcast_to(n_vars + np.arange(CALIBRATION)[None, None, :], r.shape)
        rows.append(r.ravel())
        cols.append(c.ravel())
        vals.append((-gyro.jacobians * gyro_inv_sigma[:, None, None]).ravel())
        base += 3 * (m - 1)
        rows.append(base + np.arange(CALIBRATION))
        cols.append(n_vars + np.arange(CALIBRATION))
        vals.append(theta_inv_sigma)
        n_vars += CALIBRATION
    total = base + (CALIBRATION if gyro is not None else 0)
    return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(total, n_vars))


Constraint = tuple[int, int, Rotation, np.ndarray]  # (i, j, Q ≈ R_i⁻¹ R_j, Q's covariance (3, 3), rad², axes of j)


def solve(initial: Rotation, constraints: list[Constraint], prior: Rotation | None = None,
          prior_sigma: np.ndarray | None = None, gyro: GyroIntervals | None = None, gyro_sigma: np.ndarray | None = None,
          theta_sigma: np.ndarray | None = None, near: bool = False,
          theta0: np.ndarray | None = None) -> tuple[Rotation, float, float, np.ndarray]:
    """The keyframe orientations minimising the robust sum over constraints (i, j, Q, C) of
    rᵀ C⁻¹ r, r = rotvec(Q⁻¹ R_i⁻¹ R_j), and over keyframes of |rotvec(P_k⁻¹ R_k)|² / sigma_k² (prior P, where
    given; sigma inf: none), keyframe 0 held; with gyro, also the chain of the gyroscope's relative rotations
    (gyro_sigma each) under a calibration estimated with them (prior 0, theta_sigma). Returns the
    orientations, the cost before and after, and the calibration (zeros without gyro; theta0: where it
    starts). near: the start is close already (a later round), the soft-L1 stage is skipped."""
    m = len(initial)
    if m < 2:
        return initial, 0.0, 0.0, np.zeros(CALIBRATION)
    ii = np.array([c[0] for c in constraints], dtype=int)
    jj = np.array([c[1] for c in constraints], dtype=int)
    q_inv = Rotation.concatenate([c[2] for c in constraints]).inv() if constraints else Rotation.identity(0)
    white = whitening(np.array([c[3] for c in constraints], dtype=np.float64).reshape(-1, 3, 3))
    prior = initial if prior is None else prior
    prior_inv_sigma = np.zeros(m) if prior_sigma is None else 1.0 / np.asarray(prior_sigma, dtype=np.float64)
    calibrated = gyro is not None
    args = (initial, ii, jj, q_inv, white, prior.inv(), prior_inv_sigma, gyro,
            None if not calibrated else 1.0 / np.asarray(gyro_sigma, dtype=np.float64),
            None if not calibrated else 1.0 / np.asarray(theta_sigma, dtype=np.float64))
    n_vars = 3 * (m - 1) + (CALIBRATION if calibrated else 0)
    x0 = np.zeros(n_vars)
    if calibrated and theta0 is not None:
        x0[3 * (m - 1):] = theta0
    # The robust loss on the feature pairs alone, by reweighting (a loss in least_squares itself would also
    # discount the gyroscope's chain wherever its calibration is still off, and nothing would calibrate it):
    # soft-L1 weights first (convex enough to pull a drifted start in), then Cauchy's, whose influence falls
    # off with the residual, so that a false loop closure is all but ignored.
    n = len(ii)
    x = x0
    for kind, rounds in (("soft_l1", 0 if near else IRLS_ROUNDS[0]), ("cauchy", IRLS_ROUNDS[1])):
        for _ in range(rounds):
            z = np.sum(_residuals(x, *args)[:3 * n].reshape(n, 3) ** 2, axis=1) / LOSS_SCALE**2
            weight = (1 + z) ** (-0.25 if kind == "soft_l1" else -0.5)  # the root of the loss's derivative
            weighted = args[:4] + (white * weight[:, None, None],) + args[5:]
            result = least_squares(_residuals, x, jac=_jacobian, args=weighted, x_scale="jac", method="trf",
                                   max_nfev=30)
            x = result.x
    before = float(np.sum(_residuals(x0, *args) ** 2))
    refined = Rotation.from_rotvec(np.vstack([np.zeros(3), x[:3 * (m - 1)].reshape(-1, 3)])) * initial
    theta = x[3 * (m - 1):] if calibrated else np.zeros(CALIBRATION)
    return refined, before, float(np.sum(_residuals(x, *args) ** 2)), theta


def interpolate(times: np.ndarray, keys: np.ndarray, refined_keys: Rotation, imu: Rotation) -> Rotation:
    """Every frame's orientation: the correction (refined times the IMU's inverse) at the keyframes, slerped
    over time (held beyond the first and last), times the frame's IMU orientation."""
    corrections = refined_keys * imu[keys].inv()
    if len(keys) == 1:
        return Rotation.concatenate([corrections] * len(times)) * imu
    t = np.clip(times, times[keys[0]], times[keys[-1]])
    return Slerp(times[keys], corrections)(t) * imu


def calibrate_gyroscope(intervals: GyroIntervals, constraints: list[Constraint],
                        key_t: np.ndarray, gyro: GyroNoise, theta_sigma: np.ndarray) -> np.ndarray:
    """The gyroscope's calibration (CALIBRATION,) that makes its chain between keyframes agree with the
    feature pairs (i, j, Q, C) taken close in time (each pair against the chain's product from i to j,
    within the pair's and the calibrated chain's uncertainty); robust (soft-L1), the calibration's prior 0."""
    ii = np.array([c[0] for c in constraints], dtype=int)
    jj = np.array([c[1] for c in constraints], dtype=int)
    q_inv = Rotation.concatenate([c[2] for c in constraints]).inv()
    white = whitening(np.array([c[3] + isotropic(gyro.sigma(key_t[c[1]] - key_t[c[0]], 0.0, calibrated=True))
                                for c in constraints]))

    def residuals(theta):
        turns = chain_turns(intervals.at(theta))
        r = np.einsum("nab,nb->na", white, (q_inv * turns[ii].inv() * turns[jj]).as_rotvec())
        return np.concatenate([r.ravel(), theta / theta_sigma])

    return least_squares(residuals, np.zeros(CALIBRATION), loss="soft_l1", f_scale=LOSS_SCALE, x_scale=theta_sigma,
                         method="trf", max_nfev=100).x


def refine(times: np.ndarray, metered: np.ndarray, imu: Rotation, frames, hfov_deg: float,
           camera: CameraIntrinsics, gyro: GyroNoise, seed: int = 0, gyro_stream: tuple | None = None,
           direct: DirectImages | None = None,
           progress: Callable[[float], None] = lambda fraction: None, early: EarlyFeatures | None = None) -> Refinement:
    """Refined orientations of every frame. times (K,): seconds; metered: indices of the frames taken at the
    metered exposure (the ones matched); imu: the IMU's camera-to-world orientations (K,); frames(k): frame
    k's 8-bit codes; gyro_stream: (t_ns, omega, camera-to-device mount) of the raw gyroscope, whose relative
    rotations between keyframes are then the chain, calibrated (else the fused orientation's, uncalibrated);
    direct: how keyframes are aligned directly where no feature pair reaches them (none: they are not);
    progress(fraction done), now and then; early: keyframes' features found before (stopped here).

    In three steps: the gyroscope calibrated against the pairs taken close in time (matched and gated
    against the raw gyroscope, which drifts little over a few seconds), so that its chain alone starts
    within a fraction of a degree everywhere (a drifted start would gate the true loop closures out);
    the loop closures found and gated against that start; then the joint solve, twice."""
    began = time.perf_counter()

    def phase(k: int) -> Callable[[float], None]:
        """progress within phase k of PHASE_SHARES"""
        low = sum(PHASE_SHARES[:k])
        return lambda fraction: progress(min(low + PHASE_SHARES[k] * fraction, 1.0))

    keys = select_keyframes(metered, imu, times)
    found = early.stop() if early is not None else None
    token = next(_TOKENS)
    with side_worker(enabled=len(keys) >= SIDE_KEYFRAMES) as side:
        side.call(_warm)  # (the worker starts and imports while the keyframes' features are found)
        try:
            return _refine(times, keys, imu, frames, hfov_deg, camera, gyro, seed, gyro_stream, direct, phase, side,
                           token, began, found)
        finally:
            drop_features(token)


def _refine(times, keys, imu, frames, hfov_deg, camera, gyro, seed, gyro_stream, direct, phase, side: SideWorker,
            token: int, began: float, found: dict[int, tuple] | None) -> Refinement:
    """refine's work from its keyframes on, the guided matching and the direct alignments shared with `side`."""
    key_t = times[keys]
    # (frames(k) may give the frame at KeyframeFeatures.small's size already)
    keyframes = keyframe_features(camera, direct, keys, frames, phase(0), found)
    # The features kept here (where the worker is not started, or cannot run a call, its calls run here) and, once,
    # in the worker (SIFT's whole numbers as uint8 there)
    keep_features(token, [k.bearings for k in keyframes], [k.descriptors for k in keyframes])
    side.call(keep_features, token, [k.bearings for k in keyframes], [_compact(k.descriptors) for k in keyframes])
    rng = np.random.default_rng(seed)
    matched: dict[tuple[int, int], tuple[Rotation, np.ndarray, int] | None] = {}
    aligned: dict[tuple[int, int], tuple[Rotation, np.ndarray] | None] = {}
    direct_used: set[tuple[int, int]] = set()  # the pairs the last call took from the direct alignment

    def pairs_within(pairs, expected: Rotation, gate, report: Callable[[float], None]) -> list[Constraint]:
        """The pairs matched within gate(dt, angle) (rad) of the expected orientations' (per keyframe) relative
        rotation, and agreeing with it within the same; then, for the keyframes no feature pair reaches, their
        pairs aligned directly (a bare ceiling: the 20 s drifting sweep's last 8 s). report(fraction done):
        the matching its first half, the direct alignments the second."""
        out, gated = [], {}  # per pair: the expected relative rotation and the gate's radius
        direct_used.clear()
        for i, j in sorted(pairs):
            q = expected[i].inv() * expected[j]
            gated[(i, j)] = (q, gate(key_t[j] - key_t[i], q.magnitude()))
        # The new pairs' guided matches in shares in the worker, ahead of this thread, which takes each pair's RANSAC
        # in order on the random stream the pairs share: the same matches, in the same order, as one after the other.
        new = [p for p in sorted(pairs) if p not in matched]
        shares = iter([(share, side.call(guided_all, token, [(i, j, *gated[(i, j)]) for i, j in share]))
                       for share in (new[k:k + MATCH_SHARE] for k in range(0, len(new), MATCH_SHARE))])
        guided: dict[tuple[int, int], tuple[np.ndarray, np.ndarray] | None] = {}
        for n, (i, j) in enumerate(sorted(pairs)):
            if n % 50 == 0:
                report(0.5 * n / len(pairs))
            q, radius = gated[(i, j)]
            if (i, j) not in matched:
                if (i, j) not in guided:
                    share, future = next(shares)
                    guided.update(zip(share, future.result()))
                pair_matches = guided.pop((i, j))
                matched[(i, j)] = None if pair_matches is None else match_pair(keyframes[i], keyframes[j], rng, q, radius,
                                                                               pair_matches)
            found = matched[(i, j)]
            if found is not None and (found[0].inv() * q).magnitude() < radius:
                out.append((i, j, found[0], found[1]))
        if direct is None:
            return out
        reached = {c[0] for c in out} | {c[1] for c in out}
        unreached = [(i, j) for i, j in sorted(pairs) if i not in reached or j not in reached]
        todo = [p for p in unreached if p not in aligned]
        # In shares, split between this process and the worker: SciPy's least-squares loop holds the GIL most of
        # the time, so threads did not overlap them (outdoor_sun's 643: refinement 13.6-18.1 s on two threads against
        # 12.5-14.5 s one after the other, five runs each); a process does. Each is a function of its pair alone.
        direct_shares = [todo[k:k + DIRECT_SHARE] for k in range(0, len(todo), DIRECT_SHARE)]
        futures = [side.call(align_direct_all, direct, [(keyframes[i].image, keyframes[j].image, gated[(i, j)][0])
                                                        for i, j in share]) for share in direct_shares]
        side.settle(lambda: report(0.5 + 0.5 * sum(f.done() for f in futures) / len(futures)))
        for share, future in zip(direct_shares, futures):
            for p, match in zip(share, future.result()):
                aligned[p] = None if match is None else (
                    match.rotation, match.covariance + isotropic(np.radians(PAIR_FLOOR_DEG)))
        report(1.0)
        for i, j in unreached:
            q, radius = gated[(i, j)]
            found = aligned[(i, j)]
            if found is not None and (found[0].inv() * q).magnitude() < radius:
                out.append((i, j, found[0], found[1]))
                direct_used.add((i, j))
        return out

    dts = np.diff(key_t)
    chain: list[Constraint] = []
    intervals, chain_sigma, theta_sigma = None, None, None
    theta = np.zeros(CALIBRATION)
    start = imu[keys[0]].inv() * imu[keys]  # each keyframe's rotation from the first, camera axes
    if gyro_stream is not None and len(keys) > 1:
        intervals = GyroIntervals.of(gyro_stream[0], gyro_stream[1], key_t, gyro_stream[2])
        chain_sigma = np.array([gyro.sigma(dt, 0.0, calibrated=True) for dt in dts])
        theta_sigma = gyro.calibration_sigma()
        raw = chain_turns(intervals.rotations)
        near = [p for p in candidate_pairs(key_t, raw, hfov_deg) if key_t[p[1]] - key_t[p[0]] <= LOOP_S]
        # a pair further from the raw gyroscope than it can be off over the time between is a false match
        found = pairs_within(near, raw, lambda dt, angle: np.radians(PAIR_GATE_DEG) + 3 * gyro.sigma(dt, angle),
                             phase(1))
        if found:  # (without any, the fused orientation stays the start: its gravity corrections hold the tilt)
            theta = calibrate_gyroscope(intervals, found, key_t, gyro, theta_sigma)
            start = chain_turns(intervals.at(theta))
    else:
        for i in range(len(keys) - 1):
            q = start[i].inv() * start[i + 1]
            chain.append((i, i + 1, q, isotropic(gyro.sigma(dts[i], q.magnitude()))))
    estimate = imu[keys[0]] * start  # keyframe 0 holds the gauge: the IMU's orientation there
    pairs: set[tuple[int, int]] = set()
    before = after = 0.0
    for k_round in range(ROUNDS):  # pairs chosen by the estimate so far: the second round finds what the first moved into view
        pairs.update(candidate_pairs(key_t, estimate, hfov_deg))
        # a pair further from the estimate than its chain can drift over the time between is a false match
        constraints = chain + pairs_within(pairs, estimate, lambda dt, angle: np.radians(PAIR_GATE_DEG)
                                           + 3 * gyro.sigma(dt, angle, calibrated=intervals is not None),
                                           phase(2 + k_round))
        if len(constraints) == len(chain):  # no pair at all: nothing to refine against
            break
        estimate, cost_before, after, theta = solve(estimate, constraints, None, None, intervals, chain_sigma,
                                                    theta_sigma, near=k_round > 0, theta0=theta)
        before = before or cost_before
    used = len(constraints) - len(chain)  # (keyframe 0 was held: estimate[0] is the IMU's in every case)
    direct_pairs = sum(1 for c in constraints[len(chain):] if (c[0], c[1]) in direct_used)
    return Refinement(interpolate(times, keys, estimate, imu), keys, used, len(pairs), before, after, theta,
                      direct_pairs, time.perf_counter() - began)
