"""FLIP (NVIDIA's flip-evaluator, LDR) of 8-bit frames, evaluated on boxes around the pixels that matter
rather than on whole frames, with the same values there; and the AR session's scorer, which runs it in a
worker process beside the render loop. Kept apart from the visual-regression diff (diff.py) so that the
worker imports little more than NumPy.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable
from concurrent.futures import Future

import numpy as np

from arsim.core.worker import SideWorker, side_worker

# How far FLIP's filters reach at its default 67 pixels per degree: the colour pipeline's widest CSF Gaussian
# (b = 0.04 deg²) has radius ceil(3 sqrt(0.04 / (2 pi²)) 67) = 10 pixels, the feature detectors' ceil(3 x 0.5 x
# 0.082 x 67) = 9. A pixel's error depends on the pixels within this distance only (no image-wide normalisation
# in LDR FLIP), so a box this much wider than the pixels scored gives them their full-frame values exactly; a box
# twice as wide gives every pixel of the box its full-frame value (those near its edge included).
FLIP_RADIUS = 10
FLIP_BAND = 64  # rows of masked pixels per FLIP box (masked_flip); the box adds FLIP_RADIUS above and below


def flip_box(where: np.ndarray, margin: int) -> tuple[slice, slice]:
    """The box around the pixels `where` (H, W) widened by margin, clipped to the frame."""
    rows, cols = np.flatnonzero(where.any(axis=1)), np.flatnonzero(where.any(axis=0))
    return (slice(max(rows[0] - margin, 0), rows[-1] + margin + 1),
            slice(max(cols[0] - margin, 0), cols[-1] + margin + 1))


def _flip(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(H, W) LDR FLIP of 8-bit b against a."""
    import flip_evaluator

    error, _, _ = flip_evaluator.evaluate(np.ascontiguousarray(a, dtype=np.float32) / 255,
                                          np.ascontiguousarray(b, dtype=np.float32) / 255, "LDR", applyMagma=False)
    error = np.asarray(error)
    return error[..., 0] if error.ndim == 3 else error


def flip_map(a: np.ndarray, b: np.ndarray, where: np.ndarray, margin: int = 2 * FLIP_RADIUS) -> np.ndarray:
    """(H, W) LDR FLIP of 8-bit b against a, evaluated on the box around the pixels `where` widened by
    `margin`, 0 outside it. The default margin gives the whole map its full-frame values (0 beyond FLIP_RADIUS
    of any pixel where the frames differ); FLIP_RADIUS gives them to the pixels `where` only."""
    box = flip_box(where, margin)
    error = np.zeros(a.shape[:2], np.float32)
    error[box] = _flip(a[box], b[box])
    return error


def masked_flip(reference: np.ndarray, test: np.ndarray, mask: np.ndarray) -> float:
    """Mean FLIP (LDR, sRGB inputs) of two 8-bit frames over the masked pixels (the AR session's score of each
    frame against its truth frame). The whole frame costs most of a second at 640 x 480, so FLIP is evaluated
    on one box per group of masked pixels, widened by its reach: pixels nearer each other than twice the reach
    share a box (their widened boxes would overlap), groups farther apart (an object here, another there)
    get boxes of their own rather than one box with the space between them. Every masked pixel gets its
    full-frame value, so the mean is the full frame's over the mask."""
    import cv2

    reach = 2 * FLIP_RADIUS + 1
    grown = cv2.dilate(mask.astype(np.uint8), np.ones((reach, reach), np.uint8))  # each pixel's reach, clipped to the frame
    count, labels, stats, _ = cv2.connectedComponentsWithStats(grown, connectivity=8)
    error = np.zeros(mask.shape, np.float32)
    for label in range(1, count):
        x, y, w, h = stats[label, :4]  # the group's pixels widened by FLIP_RADIUS: the dilation's box
        group = mask[y:y + h, x:x + w] & (labels[y:y + h, x:x + w] == label)
        # A group cut into bands of rows, each with the box of its own pixels widened by FLIP_RADIUS: a group
        # that runs at a slant (the row of spheres seen from the side) leaves most of its box empty otherwise.
        for top in range(0, h, FLIP_BAND):
            band = np.zeros_like(group)
            band[top:top + FLIP_BAND] = group[top:top + FLIP_BAND]
            if band.any():
                rows, cols = flip_box(band, FLIP_RADIUS)  # (in the group's box: its margin lies inside it)
                box = np.s_[y + rows.start:y + rows.stop, x + cols.start:x + cols.stop]
                scored = band[rows, cols]
                error[box][scored] = _flip(reference[box], test[box])[scored]
    return float(error[mask].mean())


def _passive_openmp() -> None:
    """flip_evaluator's OpenMP threads sleep between its loops instead of spinning: beside a caller that
    renders on the same cores, a spinning thread takes a core's time from it (a third of FLIP's CPU time
    went to spinning in an AR session). Set before flip_evaluator is first imported, when OpenMP reads it (the
    spin count as well: arsim's own, for numba's loops, would override the policy's)."""
    os.environ["OMP_WAIT_POLICY"] = "PASSIVE"
    os.environ["GOMP_SPINCOUNT"] = "0"


class FlipWorker(SideWorker):
    """masked_flip and flip_map run beside the caller (arsim.core.worker): each call returns a Future of the
    value they give (flip_worker makes one); settle lets the caller take a share of the calls still waiting."""

    def __init__(self, submit: Callable[..., Future]):
        super().__init__(submit, _passive_openmp)  # (settling here: as in the worker, where OpenMP has not started)

    def score(self, reference: np.ndarray, test: np.ndarray, mask: np.ndarray) -> Future:
        """masked_flip's value; only the mask's box travels (the box of the box is the box itself, so the
        value is masked_flip's exactly). The AR session's scorer."""
        box = flip_box(mask, FLIP_RADIUS)
        return self.call(masked_flip, reference[box], test[box], mask[box])

    def error_map(self, a: np.ndarray, b: np.ndarray, where: np.ndarray) -> Future:
        """flip_map's (H, W) map with its default margin."""
        return self.call(flip_map, a, b, where)


def flip_worker() -> contextlib.AbstractContextManager[FlipWorker]:
    """A FlipWorker whose FLIP runs in a worker process: flip_evaluator holds the GIL while it works, so a
    thread would not overlap it with the caller's rendering; a process does, on another core."""
    return side_worker(FlipWorker, initializer=_passive_openmp)
