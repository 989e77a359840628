"""The online pass's drift filter against known answers: a gyroscope bias learnt from alignments and carried
across a gap with nothing to align, a 1 degree/s bias corrected rather than gated out, a false match dropped."""

import numpy as np
from scipy.spatial.transform import Rotation

from arsim.capture.drift import DriftFilter
from arsim.capture.refine import GyroNoise

RATE = 30.0
BIAS_DPS = np.array([0.6, -0.8, 0.4])  # camera axes: about a 1 degree/s turn-on bias


def sweep(seconds: float = 20.0):
    """True camera-to-world orientations of a spiral sweep (yaw 30 degrees/s, pitch -60 -> 60) and the fused ones
    of a gyroscope with BIAS_DPS and no gravity feedback (kp = 0), at RATE frames/s."""
    t = np.arange(0.0, seconds, 1 / RATE)
    truth = Rotation.from_euler("YX", np.stack([np.radians(30.0) * t, np.radians(-60.0 + 120.0 * t / seconds)], -1))
    steps = (truth[:-1].inv() * truth[1:]) * Rotation.from_rotvec(np.radians(BIAS_DPS) / RATE * np.ones((len(t) - 1, 1)))
    fused = [truth[0]]
    for step in steps:
        fused.append(fused[-1] * step)
    return t, truth, Rotation.concatenate(fused)


def run(measure, t, truth, fused, every: int = 3):
    """The filter's orientations frame by frame; measure(k) says whether frame k's truth (0.05 degrees of noise)
    is given as an alignment. Returns (orientations, filter, accepted count)."""
    gyro = GyroNoise(noise_density=5e-5, bias=np.radians(1.0), scale_factor=1e-4, misalignment=1e-4, random_walk=1e-5)
    f = DriftFilter(fused, t, gyro, accel_bias=1e-6, kp=0.0, corrects_heading=False, probe_size=512)
    rng = np.random.default_rng(1)
    out, accepted = [], 0
    for k in range(len(t)):
        f.predict(k)
        if k and k % every == 0 and measure(k):
            accepted += f.update(truth[k] * Rotation.from_rotvec(rng.normal(0.0, np.radians(0.05), 3)))
        out.append(f.correction() * fused[k])
    return Rotation.concatenate(out), f, accepted


def errors_deg(a: Rotation, b: Rotation) -> np.ndarray:
    return np.degrees((a * b.inv()).magnitude())


def test_the_bias_learnt_from_alignments_carries_the_orientation_across_a_gap():
    t, truth, fused = sweep()
    estimate, f, accepted = run(lambda k: t[k] < 10.0, t, truth, fused)
    bias, sigma = f.bias
    # measured: 0.02, 0.01, 0.03 off with sigma 0.018 degrees/s (the model's white drift limits it)
    assert np.all(np.abs(np.degrees(bias) - BIAS_DPS) < np.minimum(0.05, 3 * np.degrees(sigma)))
    gap = t >= 10.0
    assert errors_deg(estimate, truth)[~gap].max() < 0.2  # measured 0.11
    # 10 s with nothing to align: measured 0.40 degrees at the end, against 8.5 for the correction held from the
    # last alignment (what a filter without the bias does)
    held = (estimate[gap][0] * fused[gap][0].inv()) * fused[gap]
    assert errors_deg(estimate, truth)[gap].max() < min(0.5, 0.1 * errors_deg(held, truth[gap]).max())
    assert accepted == sum(1 for k in range(1, len(t)) if k % 3 == 0 and t[k] < 10.0)  # none gated out


def test_a_false_match_is_dropped_and_a_true_one_after_a_long_gap_is_taken():
    t, truth, fused = sweep(12.0)
    f = run(lambda k: t[k] < 4.0, t, truth, fused)[1]
    for k in range(f.k + 1, len(t)):
        f.predict(k)
        if t[k] >= 6.0:
            break
    before = f.x.copy()
    assert not f.update(truth[f.k] * Rotation.from_euler("x", 3.0, degrees=True))  # 3 degrees after 2 s: impossible
    assert np.array_equal(f.x, before)
    assert f.update(truth[f.k])
    assert errors_deg(f.correction() * fused[f.k], truth[f.k]) < 0.05
