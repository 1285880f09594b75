"""Dask clusters for the Dask executor: a local cluster started for one run, or the client
of an existing one, checked before any job is submitted.

Start the workers of an existing cluster with
``dask worker tcp://host:8786 --nthreads 1 --preload flows.worker_preload``.
"""

from __future__ import annotations

import os
import socket
import threading
from pathlib import Path

import dask
from distributed import Client, LocalCluster

from flows.prefect_env import free_port

#: Dask's nannies start local workers with MALLOC_TRIM_THRESHOLD_=65536, which hands every
#: large numpy temporary back to the OS and faults it in again: numpy-heavy stages ran up to
#: 1.6x slower in a worker than in this process (evaluate 8.4-9.9 s vs 5.4-6.2 s); keep glibc's
#: default. (Workers of an existing cluster keep whatever their own config says.)
NO_MALLOC_TRIM = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}

#: Thread-pool sizes of the numerical libraries, read by each worker process at start
THREAD_ENV = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def worker_thread_env(
    workers: int, cores: int | None = None, per_worker: int | None = None
) -> dict[str, str]:
    """Environment for local Dask workers: the machine's cores shared out between them
    (or ``per_worker`` threads each).

    Each worker would otherwise size its numba (FEM solve), OpenMP and BLAS pools to every
    core, and workers x cores spinning threads on the same cores ran slower than one process.
    """
    per_worker = per_worker or max(1, (cores or os.cpu_count() or 1) // max(1, workers))
    return {name: str(per_worker) for name in THREAD_ENV}


def connect(address: str, timeout_s: float = 10.0) -> Client:
    """A client of the scheduler at ``address``; a one-line error when none answers."""
    try:
        return Client(address, timeout=f"{timeout_s}s")
    except OSError as exc:
        raise ValueError(
            f"--dask-address {address}: no Dask scheduler answers there ({exc}); start one "
            "with `dask scheduler` or check the address"
        ) from None


def check_workers(client: Client, address: str, local_api: bool, timeout_s: float = 60.0) -> None:
    """Refuse, in one line, a cluster with no worker within ``timeout_s``, and workers on
    other machines when the Prefect API listens on 127.0.0.1 here (``local_api``: they
    cannot reach it)."""
    try:
        client.wait_for_workers(1, timeout=timeout_s)
    except TimeoutError:
        raise ValueError(
            f"--dask-address {address}: the scheduler has no workers; start them with "
            f"`dask worker {address} --nthreads 1 --preload flows.worker_preload`"
        ) from None
    hosts = set(client.run(socket.gethostname).values())
    if local_api and hosts - {socket.gethostname()}:
        raise ValueError(
            f"--dask-address {address}: workers on {', '.join(sorted(hosts))} cannot reach the "
            "Prefect server on this machine's 127.0.0.1; start a server they can reach "
            "(`prefect server start --host 0.0.0.0`) and set PREFECT_API_URL to it"
        )


class LocalDask:
    """A local Dask cluster for one run, started in a background thread (so that it comes
    up while Prefect's server does) and closed in one (while the report is written)."""

    def __init__(self, workers: int, scratch: Path, env: dict[str, str]) -> None:
        self.address = f"tcp://127.0.0.1:{free_port()}"
        self._cluster: LocalCluster | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(
            target=self._start, args=(workers, scratch, env), name="physanim-dask-start"
        )
        self._thread.start()

    def _start(self, workers: int, scratch: Path, env: dict[str, str]) -> None:
        try:
            with dask.config.set(NO_MALLOC_TRIM):
                self._cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    scheduler_port=int(self.address.rsplit(":", 1)[1]),
                    dashboard_address=None,
                    local_directory=str(scratch),
                    preload=["flows.worker_preload"],
                    env=env,
                )
        except BaseException as exc:  # re-raised in the caller's thread by wait()
            self._error = exc

    def wait(self) -> str:
        """The scheduler address once every worker is up; raises if the cluster failed."""
        self._thread.join()
        if self._error is not None:
            raise RuntimeError(f"local Dask cluster did not start: {self._error}") from self._error
        return self.address

    def close_in_background(self) -> threading.Thread:
        """Start closing the cluster; join the returned thread before exiting."""
        self._thread.join()
        thread = threading.Thread(target=self._close, name="physanim-dask-close")
        thread.start()
        return thread

    def _close(self) -> None:
        if self._cluster is not None:
            self._cluster.close()
