"""arsim: a simulator of a mobile AR app that captures real-world light and renders virtual objects with it."""

import os as _os
import sys as _sys

__version__ = "0.1.0"

# Threads of the numeric libraries (README: Threads), set before they load where arsim is imported first (the
# command line): OpenBLAS on one thread, as arsim's matrices are small and its own threads keep the cores busy
# (idle BLAS threads spun through a twentieth of a run's CPU time, and its results no longer depend on the core
# count); libgomp's threads (numba's parallel loops) spin 10,000 rounds after a loop instead of 300,000 before
# they sleep (a twentieth of a run's CPU time spun away beside OpenCV and llvmpipe); OpenCV's thread pool sleeps
# at once instead of spinning and yielding while it waits (its yields took a third of a cold run's system
# time). A value already set is kept.
if "OPENBLAS_NUM_THREADS" not in _os.environ:
    _os.environ["OPENBLAS_NUM_THREADS"] = "1"
    if "numpy" in _sys.modules:  # (loaded before arsim: its OpenBLAS read the environment already)
        from threadpoolctl import threadpool_limits as _threadpool_limits

        _threadpool_limits(1, user_api="blas")
_os.environ.setdefault("GOMP_SPINCOUNT", "10000")
_os.environ.setdefault("OPENCV_THREAD_POOL_ACTIVE_WAIT_MAIN", "0")
_os.environ.setdefault("OPENCV_THREAD_POOL_ACTIVE_WAIT_WORKER", "0")
