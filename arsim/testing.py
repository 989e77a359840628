"""Visual regression in a user's own test suite: assert that a run's frames match a baseline.

A pytest plugin: pytest alone imports this module (arsim's commands never do, so they run without pytest).

As a function::

    from arsim.testing import assert_frames_match
    assert_frames_match("runs/indoor", "baselines/indoor", max_flip=0.001)

or, with pytest (arsim registers this module as a plugin), the `arsim_baseline` fixture, which writes the
diff (heatmaps and index.html) under the test's tmp_path and, run with `--arsim-update-baseline`, makes
the frames the new baseline instead::

    def test_indoor_frames(arsim_baseline):
        arsim_baseline("runs/indoor", "baselines/indoor", max_flip=0.001)

A failure names the frames over the threshold, by how much, and where their heatmaps are.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from arsim.core.errors import ArsimError
from arsim.evaluate.diff import DEFAULT_MAX_FLIP, DiffResult, run_diff, update_baseline


def assert_frames_match(frames: str | os.PathLike, baseline: str | os.PathLike, max_flip: float = DEFAULT_MAX_FLIP,
                        out_dir: str | os.PathLike | None = None) -> DiffResult:
    """Compare the frames (a run directory or a folder of frames) with the baseline's; AssertionError
    when a frame's mean FLIP exceeds max_flip or a frame is missing on either side."""
    out = Path(out_dir) if out_dir is not None else None
    try:
        result = run_diff(Path(baseline), Path(frames), out, max_flip)
    except ArsimError as exc:
        raise AssertionError(str(exc)) from None
    if not result.passed:
        page = f"\ndiff page: {out / 'index.html'}" if out is not None else ""
        raise AssertionError(f"the frames of {frames} do not match the baseline {baseline}:\n{result.message()}{page}")
    return result


def pytest_addoption(parser) -> None:
    parser.addoption("--arsim-update-baseline", action="store_true", default=False,
                     help="arsim_baseline: write the frames as the new baseline instead of comparing them")


@pytest.fixture
def arsim_baseline(request, tmp_path):
    """A function (frames, baseline, max_flip=0) that asserts the frames match the baseline, or with
    --arsim-update-baseline writes them as the baseline."""
    update = request.config.getoption("--arsim-update-baseline", default=False)

    def check(frames, baseline, max_flip: float = DEFAULT_MAX_FLIP):
        if update:
            return update_baseline(frames, baseline)
        return assert_frames_match(frames, baseline, max_flip, out_dir=tmp_path / "arsim-diff")

    return check
