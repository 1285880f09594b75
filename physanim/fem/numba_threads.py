"""Choose numba's threading layer for the FEM's parallel kernels (import before compiling).

numba tries TBB first; a TBB older than it needs (open3d and fTetWild bring one) makes it warn
on every first parallel launch before falling back. OpenMP first, then TBB, then numba's own
workqueue (which is not safe for concurrent launches from several Python threads).
"""

import functools
import time
from collections.abc import Callable
from typing import ParamSpec, TypeVar

import numba
import numpy as np

numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]

P = ParamSpec("P")
R = TypeVar("R")


def keeps_thread_count(fn: Callable[P, R]) -> Callable[P, R]:
    """Decorator: numba's thread count is restored when ``fn`` returns or raises (``fn`` may
    lower it with :func:`faster_thread_count`)."""

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        most = numba.get_num_threads()
        try:
            return fn(*args, **kwargs)
        finally:
            numba.set_num_threads(most)

    return wrapper


def faster_thread_count(work: Callable[[], object], most: int, repeats: int = 3) -> int:
    """``most`` or 1: the numba thread count that runs ``work`` faster now (medians of
    ``repeats`` runs each). On cores busy with other processes a parallel kernel waits at
    every barrier for a descheduled thread: measured 3x slower solves on two shared cores
    with two threads than with one."""
    if most <= 1:
        return 1
    medians = {}
    for n in (most, 1):
        numba.set_num_threads(n)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            work()
            times.append(time.perf_counter() - t0)
        medians[n] = float(np.median(times))
    best = min(medians, key=medians.__getitem__)
    numba.set_num_threads(best)
    return best
