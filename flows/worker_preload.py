"""Dask worker preload: native libraries loaded by the worker's main thread before any task,
and the modules every sweep task imports (Prefect's task engine, the flows: about 3 s), so
that a worker's first task does not wait for them.

Local sweep clusters preload it; start the workers of an existing cluster with
``dask worker tcp://host:8786 --preload flows.worker_preload`` (see ``physanim.native``).
"""

from __future__ import annotations

from typing import Any

from physanim.native import load_in_main_thread


def dask_setup(worker: Any) -> None:
    """Called by Dask in the worker's main thread (event loop) when the worker starts."""
    load_in_main_thread()
    import flows.executors  # noqa: F401  (imports prefect, prefect_dask and the pipeline)
