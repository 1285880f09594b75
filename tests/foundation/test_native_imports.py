"""Stage code loading pymeshlab, Open3D and usd-core in a worker thread: the process exits
cleanly, and does not hang."""

import subprocess
import sys

import pytest


@pytest.mark.parametrize(
    "stage_imports",
    [
        # a stage needing Open3D (ingest, capture), then one needing pymeshlab (mesh)
        ["import physanim.capture.bag_source, open3d", "import physanim.mesh.scan_io"],
        ["import scipy.sparse, physanim.capture.actor"],
    ],
)
def test_stage_threads_after_main_thread_preload_exit_cleanly(stage_imports: list[str]) -> None:
    # what the flows do: load_in_main_thread(), then stages in threads (Prefect, Dask). With
    # these imports in a thread and no preload, pymeshlab 2025.7 + open3d 0.20 made the
    # process abort at exit (glibc malloc_consolidate, status 134), measured here
    body = "".join(f"    {line}\n" for line in stage_imports)
    code = (
        "import threading\nfrom physanim.native import load_in_main_thread\n"
        f"assert load_in_main_thread()\ndef stage():\n{body}"
        "t = threading.Thread(target=stage)\nt.start()\nt.join()\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-500:]


CHURN_WHILE_USD_LOADS = """
import threading
import numpy as np
from physanim.native import load_in_main_thread
assert load_in_main_thread()
stop = False
def churn():  # what evaluate does beside export: temporaries numpy may reuse
    a = np.ones(100_000)
    while not stop:
        b = -(a + 1.0)
def export():
    from pxr import Kind, Sdf, Usd, UsdGeom, Vt
threads = [threading.Thread(target=churn) for _ in range(2)]
for t in threads:
    t.start()
loader = threading.Thread(target=export)
loader.start()
loader.join()
stop = True
for t in threads:
    t.join()
"""


def test_usd_loaded_in_a_thread_beside_numpy_does_not_hang() -> None:
    # without the preload, 3 of 9 such runs hung for ever (usd-core 25.x: dlopen drops the
    # GIL under the loader's lock; numpy's temporary check waits for that lock holding it)
    pytest.importorskip("pxr")
    for _ in range(6):
        proc = subprocess.run(
            [sys.executable, "-c", CHURN_WHILE_USD_LOADS], capture_output=True, text=True,
            timeout=60,
        )  # fmt: skip
        assert proc.returncode == 0, proc.stderr[-500:]
