"""Progress display for long work: a rich bar on a terminal; plain lines on stderr elsewhere (a CI log, a
batch job, a pipe), so that a long run shows where it is without drowning the log.

The lines, one per stage start, about every 10 % of its progress and one at its end, each with the time
since the stage began:

    [arsim] 2/6 capturing the light probe: started
    [arsim] 2/6 capturing the light probe: 40 % (23.1 s)
    [arsim] 2/6 capturing the light probe: done (58.2 s)

$ARSIM_PROGRESS chooses: unset or "auto" (the bar on a terminal, lines elsewhere), "lines" (lines on a terminal
too), "off" (nothing).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Callable, Iterator
from typing import TextIO

from arsim.core.errors import ArsimError

PROGRESS_ENV = "ARSIM_PROGRESS"
PROGRESS_MODES = ("auto", "lines", "off")
LINE_STEP = 0.10  # a progress line at most every 10 % of a stage (a long log stays readable)
PREFIX = "[arsim]"


def progress_mode() -> str:
    """$ARSIM_PROGRESS as one of PROGRESS_MODES (unset: auto); ArsimError for anything else."""
    mode = os.environ.get(PROGRESS_ENV, "").strip().lower() or "auto"
    if mode not in PROGRESS_MODES:
        raise ArsimError(f"{PROGRESS_ENV}={os.environ[PROGRESS_ENV]!r} is not a progress mode; "
                         f"set it to one of {', '.join(PROGRESS_MODES)} (or unset it)")
    return mode


class ProgressLines:
    """A stage's plain progress lines: start, then at most one per `step` of progress, then the end.

    `every_update`: a line at each update that moves the progress (batch: one per finished run), however
    small the step. `clock` (seconds) and `stream` are injectable for tests."""

    def __init__(self, description: str, total: float, stream: TextIO | None = None,
                 clock: Callable[[], float] = time.monotonic, step: float = LINE_STEP, every_update: bool = False):
        self.stage, self.label, self.total = description, description, float(total)
        self.stream, self.clock, self.step, self.every_update = stream, clock, step, every_update
        self.start = clock()
        self.shown = 0.0  # the fraction of the last line
        self._line("started")

    def _line(self, text: str) -> None:
        stream = self.stream if self.stream is not None else sys.stderr
        print(f"{PREFIX} {self.stage}: {text}", file=stream, flush=True)

    def _detail(self) -> str:
        """What an update's description adds to the stage's name (e.g. the share of the sphere covered)."""
        if self.label == self.stage:
            return ""
        return ", " + self.label.removeprefix(self.stage + ": ")

    def elapsed(self) -> float:
        return self.clock() - self.start

    def update(self, completed: float | None = None, description: str | None = None) -> None:
        if description is not None:
            self.label = description
        if completed is None or self.total <= 0:
            return
        fraction = min(max(completed / self.total, 0.0), 1.0)
        due = fraction > self.shown if self.every_update else fraction >= self.shown + self.step - 1e-9
        if due:
            self.shown = fraction
            self._line(f"{100 * fraction:.0f} % ({self.elapsed():.1f} s){self._detail()}")

    def end(self, failed: bool = False) -> None:
        self._line(f"{'stopped' if failed else 'done'} ({self.elapsed():.1f} s)")


def _silent(completed=None, description=None) -> None:
    return None


@contextlib.contextmanager
def progress_bar(description: str, total: float, every_update: bool = False) -> Iterator[Callable[..., None]]:
    """Yield update(completed=None, description=None): set the stage's progress (out of total) or its label.
    A bar on a terminal; elsewhere ProgressLines (every_update: a line per update, e.g. per finished run)."""
    mode = progress_mode()
    if mode == "off":
        yield _silent
        return
    if mode == "lines" or not sys.stderr.isatty():
        lines = ProgressLines(description, total, every_update=every_update)
        try:
            yield lines.update
        except BaseException:
            lines.end(failed=True)
            raise
        lines.end()
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(), transient=True) as bar:
        task = bar.add_task(description, total=total)

        def update(completed=None, description=None):
            bar.update(task, completed=completed, description=description)

        yield update


@contextlib.contextmanager
def quiet_stage(description: str) -> Iterator[Callable[..., None]]:
    """A stage that shows nothing: the library's default where no command shows it (a test calling a stage
    itself, a stage nested inside one already shown). update() does nothing."""
    yield _silent
