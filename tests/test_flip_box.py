"""FLIP evaluated on a box around the pixels that matter gives them their full-frame values exactly."""

import flip_evaluator
import numpy as np
import pytest

from arsim.evaluate.diff import compare_images
from arsim.evaluate.flip import FLIP_RADIUS, flip_map, masked_flip


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


def test_objects_apart_slanted_and_at_the_frames_edge_get_their_full_frame_values():
    # masked_flip's boxes: one per group of masked pixels, cut into bands of rows; groups far apart, a slanted
    # row of blobs taller than a band and a group on the frame's corner each get the full frame's values
    rng = np.random.default_rng(5)
    y, x = np.mgrid[0:300, 0:400]
    a = np.stack([(x * 0.9) % 255, (y * 1.3) % 255, ((x - y) * 0.6) % 255], axis=-1).astype(np.uint8)
    b = np.clip(a.astype(int) + rng.integers(-35, 35, a.shape), 0, 255).astype(np.uint8)
    mask = np.zeros(a.shape[:2], bool)
    mask[20:50, 300:340] = True  # apart from the others
    for k in range(12):  # a slanted row of small blobs, 180 rows tall
        mask[60 + 15 * k:68 + 15 * k, 20 + 12 * k:28 + 12 * k] = True
    mask[285:300, 385:400] = True  # on the corner
    assert masked_flip(a, b, mask) == pytest.approx(float(full_frame(a, b)[mask].mean()), rel=0, abs=1e-7)
    # the same values as the error map's over the mask, to the bit: the session takes an estimate's score as
    # the mean of the map it shows
    assert masked_flip(a, b, mask) == float(flip_map(a, b, mask)[mask].mean())


def test_the_workers_scores_are_masked_flips_and_an_interruption_drops_the_rest(frames):
    from arsim.evaluate.flip import flip_worker

    a, b, where = frames
    with flip_worker() as flip:
        assert flip.score(a, b, where).result() == masked_flip(a, b, where)
        assert np.array_equal(flip.error_map(a, b, where).result(), flip_map(a, b, where))
    with pytest.raises(KeyboardInterrupt):
        with flip_worker() as flip:
            futures = [flip.score(a, b, where) for _ in range(40)]
            raise KeyboardInterrupt
    assert any(f.cancelled() for f in futures)  # (not all 40 computed before the worker stopped)


def test_settle_takes_the_calls_not_yet_begun_from_the_back_with_the_workers_values(frames):
    from arsim.evaluate.flip import flip_worker

    a, b, where = frames
    expected = masked_flip(a, b, where)
    with flip_worker() as flip:
        futures = [flip.score(a, b, where) for _ in range(16)]
        flip.settle()
        assert flip.taken > 0  # (the worker is handed two at a time: the rest wait to be taken)
        assert [f.result() for f in futures] == [expected] * 16


def test_a_call_the_worker_process_could_not_run_is_computed_by_the_caller():
    """A worker that died or never started (a script that starts it at import without the __main__ guard, run
    again by the spawned process) breaks its pool: the calls it held are computed by the caller instead."""
    from concurrent.futures import Future
    from concurrent.futures.process import BrokenProcessPool

    from arsim.core.worker import SideWorker

    pending = []

    def submit(function, *args):
        pending.append(Future())
        return pending[-1]

    def broken(function, *args):
        raise BrokenProcessPool("the worker died")

    worker = SideWorker(submit)
    futures = [worker.call(sum, [1, 2, k]) for k in range(3)]
    for future in pending:  # the pool's manager marks every call it held broken
        future.set_running_or_notify_cancel()
        future.set_exception(BrokenProcessPool("the worker died"))
    assert [f.result(timeout=5) for f in futures] == [3, 4, 5]
    assert SideWorker(broken).call(sum, [2, 3]).result(timeout=5) == 5  # (submitted to a pool already broken)
