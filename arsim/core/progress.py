"""Progress display for long work: a rich bar on a terminal, silence when output is not a terminal."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator


@contextlib.contextmanager
def progress_bar(description: str, total: float) -> Iterator[Callable[..., None]]:
    """Yield update(completed=None, description=None): set the bar's progress or its label."""
    if not sys.stderr.isatty():
        yield lambda completed=None, description=None: None
        return
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(), transient=True) as bar:
        task = bar.add_task(description, total=total)

        def update(completed=None, description=None):
            bar.update(task, completed=completed, description=description)

        yield update


@contextlib.contextmanager
def quiet_stage(description: str) -> Iterator[Callable[..., None]]:
    """A stage that shows nothing (runs in batch, in tests): update() does nothing."""
    yield lambda completed=None, description=None: None
