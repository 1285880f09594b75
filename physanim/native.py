"""Native libraries that the main thread must load before stage code runs in worker threads.

Measured here (pymeshlab 2025.7, open3d 0.20, scipy 1.17): a process in which a thread other
than the main one imports open3d then pymeshlab, or scipy.sparse, pymeshlab then open3d, aborts
at exit with glibc's "malloc_consolidate(): unaligned fastbin chunk detected" (status 134, or a
Dask worker killed by signal 6). With pymeshlab loaded by the main thread first, the same
imports of every stage module in a thread exit cleanly (Open3D alone first does not help).
Likewise usd-core (25.x; the export stage's USD writer): loading its libraries drops the GIL
inside ``dlopen`` while holding the dynamic loader's lock, and a thread in numpy that then
checks whether it may reuse a temporary (``check_callers``, which walks the stack through the
loader) waits for that lock holding the GIL: both wait for ever. A pipeline hung so, export
importing ``pxr`` while evaluate ran; in a small script (two threads negating temporaries,
a third importing ``pxr``) 3 runs of 9 hung, none with ``pxr`` loaded by the main thread first.
Prefect runs stages in worker threads and Dask in executor threads, so the flows call
``load_in_main_thread`` first, and Dask workers preload ``flows.worker_preload``.
"""

from __future__ import annotations

import contextlib
import threading


def load_in_main_thread() -> bool:
    """Import pymeshlab, Open3D and (where installed) usd-core's modules if this is the main
    thread; True when it was."""
    if threading.current_thread() is not threading.main_thread():
        return False  # too late to help here; the stages load them where they need them
    import open3d  # noqa: F401  (loaded with pymeshlab in the measurements above)
    import pymeshlab  # noqa: F401

    with contextlib.suppress(ImportError):  # the export extra; the stage says how to get it
        from pxr import Kind, Sdf, Usd, UsdGeom, Vt  # noqa: F401  (what export/usd.py loads)
    return True
