"""Native libraries that the main thread must load before stage code runs in worker threads.

Measured here (pymeshlab 2025.7, open3d 0.20, scipy 1.16): a process in which pymeshlab is
first imported by a thread other than the main one, together with Open3D (or scipy.sparse and
Open3D), aborts at exit with glibc's "malloc_consolidate(): unaligned fastbin chunk detected"
(status 134, or a Dask worker killed by signal 6). Loaded by the main thread first, the same
imports and stages exit cleanly. Prefect runs stages in worker threads and Dask in executor
threads, so the flows call ``load_in_main_thread`` first, and Dask workers preload
``flows.worker_preload``.
"""

from __future__ import annotations

import threading


def load_in_main_thread() -> bool:
    """Import pymeshlab and Open3D if this is the main thread; True when it was."""
    if threading.current_thread() is not threading.main_thread():
        return False  # too late to help here; the stages load them where they need them
    import open3d  # noqa: F401  (loaded with pymeshlab in the measurements above)
    import pymeshlab  # noqa: F401

    return True
