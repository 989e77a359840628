"""A worker process beside the caller, for work that holds the GIL (FLIP's evaluator, SciPy's least-squares
loop): a thread would not overlap it with the caller's own work, a process does, on another core. The caller
submits calls and gets futures; when it has nothing else to do it settles, taking the calls the worker has not
begun from the back of the queue while the worker works from the front. A call computes the same function
of the same arguments wherever it runs, so the values do not depend on who took it.
"""

from __future__ import annotations

import collections
import contextlib
import functools
import multiprocessing
import os
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool


class SideWorker:
    """Calls run beside the caller: each returns a Future of the function's value (side_worker makes one).
    settle lets the caller take a share of the calls still waiting."""

    def __init__(self, submit: Callable[..., Future], before_settling: Callable[[], None] = lambda: None):
        self._submit = submit
        self._before_settling = before_settling
        self._waiting = collections.deque()  # (ours, the worker's, function, args) of the calls not yet done
        self.taken = 0  # calls settle computed here

    def call(self, function: Callable, *args) -> Future:
        """function(*args) in the worker (a module-level function: it travels by name), as a Future."""
        try:
            theirs = self._submit(function, *args)
        except BrokenProcessPool:  # (the worker could not start or died: see _copy_outcome)
            return _done(function, *args)
        if theirs.done():  # (computed in turn: _done)
            return theirs
        ours = Future()
        theirs.add_done_callback(functools.partial(_copy_outcome, ours, function, args))
        while self._waiting and self._waiting[0][1].done():  # (the worker takes them in order)
            self._waiting.popleft()
        self._waiting.append((ours, theirs, function, args))
        return ours

    def settle(self, taken: Callable[[], None] = lambda: None) -> None:
        """The calls the worker has not begun, computed here from the last while it works from the first,
        until it has begun them all: the caller, done with its own work, halves the worker's backlog instead
        of waiting for all of it. taken() is called here after each call computed here."""
        self._before_settling()
        while self._waiting:
            ours, theirs, function, args = self._waiting.pop()
            # (ours running first: the worker's cancellation then leaves it to be computed here)
            if theirs.done() or not ours.set_running_or_notify_cancel():
                continue
            if theirs.cancel():  # (not begun: it never will be)
                self.taken += 1
                _compute(ours, function, args)
                taken()


def _copy_outcome(ours: Future, function: Callable, args: tuple, theirs: Future) -> None:
    """The worker's outcome given to the caller's future: cancelled with it (the worker stopped), except where
    settle took the call (then running, it cannot be cancelled, and settle gives its value). Where the worker
    process died or could not start (a script that starts it at import, without the `if __name__ ==
    "__main__":` guard, which the spawned process runs again), the call is computed here instead."""
    if theirs.cancelled():
        ours.cancel()
    elif isinstance(error := theirs.exception(), BrokenProcessPool):
        if ours.running() or ours.set_running_or_notify_cancel():  # (running: settle marked it, the worker had it)
            _compute(ours, function, args)
    elif error is not None:
        ours.set_exception(error)
    else:
        ours.set_result(theirs.result())


def _compute(ours: Future, function: Callable, args: tuple) -> None:
    """function(*args) computed here into ours (running), its exception as well."""
    try:
        ours.set_result(function(*args))
    except Exception as e:
        ours.set_exception(e)


def _done(function, *args) -> Future:
    done = Future()
    done.set_result(function(*args))
    return done


@contextlib.contextmanager
def side_worker(kind: type[SideWorker] = SideWorker, initializer: Callable[[], None] | None = None,
                enabled: bool = True) -> Iterator[SideWorker]:
    """A `kind` of SideWorker whose calls run in a spawned worker process (initializer() run there first),
    shut down on leaving; interrupted, the calls not yet begun are dropped, not waited for. Where the worker
    could not start (a script read from standard input: a spawned process cannot import it) or enabled is
    false, each call is computed in turn on submission."""
    main_file = getattr(sys.modules["__main__"], "__file__", None)
    if not enabled or (main_file is not None and not os.path.isfile(main_file)):
        yield kind(_done)
        return
    pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"), initializer=initializer)
    try:
        yield kind(pool.submit)
    except BaseException:
        pool.shutdown(wait=True, cancel_futures=True)
        raise
    pool.shutdown(wait=True)
