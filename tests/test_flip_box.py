"""FLIP evaluated on a box around the pixels that matter gives them their full-frame values exactly."""

import flip_evaluator
import numpy as np
import pytest

from arsim.evaluate.diff import FLIP_RADIUS, compare_images, flip_map, masked_flip


def full_frame(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    error, _, _ = flip_evaluator.evaluate(a.astype(np.float32) / 255, b.astype(np.float32) / 255, "LDR", applyMagma=False)
    error = np.asarray(error)
    return error[..., 0] if error.ndim == 3 else error


@pytest.fixture(scope="module")
def frames():
    rng = np.random.default_rng(3)
    # a smooth background with edges (FLIP's feature detectors respond to them) and noise where they differ
    y, x = np.mgrid[0:160, 0:200]
    a = np.stack([(x * 1.2) % 255, (y * 1.5) % 255, ((x + y) * 0.7) % 255], axis=-1).astype(np.uint8)
    a[40:60, :] = 30
    b = a.copy()
    where = np.zeros(a.shape[:2], bool)
    where[60:95, 70:130] = True
    b[where] = np.clip(a[where].astype(int) + rng.integers(-40, 40, (where.sum(), 3)), 0, 255).astype(np.uint8)
    return a, b, where


def test_the_masked_score_equals_the_full_frames_at_the_masked_pixels(frames):
    a, b, where = frames
    assert masked_flip(a, b, where) == pytest.approx(float(full_frame(a, b)[where].mean()), rel=0, abs=1e-7)


def test_a_box_narrower_than_flips_reach_would_change_the_score(frames):
    # the check above can fail: FLIP_RADIUS is no wider than it must be
    a, b, where = frames
    truth = full_frame(a, b)[where]
    narrow = flip_map(a, b, where, margin=FLIP_RADIUS - 2)[where]
    assert np.abs(narrow - truth).max() > 1e-4


def test_the_diff_maps_error_equals_the_full_frames_everywhere(frames):
    a, b, _ = frames
    _, error = compare_images(a, b)
    np.testing.assert_allclose(error, full_frame(a, b), rtol=0, atol=1e-7)
