"""Choose numba's threading layer for the FEM's parallel kernels (import before compiling).

numba tries TBB first; a TBB older than it needs (open3d and fTetWild bring one) makes it warn
on every first parallel launch before falling back. OpenMP first, then TBB, then numba's own
workqueue (which is not safe for concurrent launches from several Python threads).
"""

import functools
import statistics
import time
from collections import deque
from collections.abc import Callable
from typing import ParamSpec, TypeVar

import numba
import numpy as np

numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]

P = ParamSpec("P")
R = TypeVar("R")


def work_partitions(n_threads: int | None = None) -> int:
    """How many pieces a parallel kernel splits its work into: ``n_threads`` when given, else
    numba's thread pool size (NUMBA_NUM_THREADS), not the current thread count. A run that
    lowers the thread count after timing it (:func:`faster_thread_count`, ``ThreadTrials``)
    then runs the same pieces on fewer threads, so its sums, and its results, are the same
    bytes whichever count it picked."""
    return max(1, int(n_threads or numba.config.NUMBA_NUM_THREADS))


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


class ThreadTrials:
    """Chooses numba's thread count from timed units of real work (frames): every ``every``-th
    unit runs on the count not in use (``most`` or 1), and the run switches to it when that
    unit was faster, per unit of size, than 0.9 times the median of the last ``window`` units
    on the count in use. Other processes come and go; probing them with discarded solves
    instead cost 6 solves every 30 frames (0.12 s of a 3 s simulate on the demo)."""

    def __init__(self, most: int, every: int = 30, window: int = 8) -> None:
        self.most, self.every = most, every
        self.best = numba.get_num_threads()
        self._recent: deque[float] = deque(maxlen=window)
        self._trial = False

    def start(self, k: int) -> int:
        """Sets numba's thread count for unit k (k = 1, 2, ...) and returns it."""
        self._trial = self.most > 1 and k % self.every == 0 and len(self._recent) >= 3
        threads = (1 if self.best == self.most else self.most) if self._trial else self.best
        numba.set_num_threads(threads)
        return threads

    def finish(self, seconds: float, size: float = 1.0) -> None:
        """Unit started last took ``seconds`` for ``size`` units of work (0: its work is not
        comparable to the others', and it is not counted)."""
        if size <= 0:
            return
        per_unit = seconds / size
        if not self._trial:
            self._recent.append(per_unit)
        elif per_unit < 0.9 * statistics.median(self._recent):
            self.best = numba.get_num_threads()
            self._recent.clear()
