"""Shared by the benchmark scripts: the best of several timed runs."""

import time


def best_of(repeat: int, fn) -> float:
    """Seconds of the fastest of `repeat` calls of fn (the least disturbed by other load)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)
