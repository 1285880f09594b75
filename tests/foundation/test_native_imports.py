"""Stage code loading pymeshlab and Open3D in a worker thread: the process exits cleanly."""

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
