"""Read-only and full disks: one clear error line, nothing half-written, the store unchanged."""

from __future__ import annotations

import ctypes
import os
import resource
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from physanim.store import StageStore
from physanim.store.stage_store import TMP
from tests.commands import ROOT, TOY, invoke, physanim, physanim_env
from tests.reliability.conftest import assert_store_tells_the_truth

CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH, PR_CAPBSET_DROP = 1, 2, 24


def _as_plain_user() -> None:
    """preexec_fn: permission bits apply even to root (drops the DAC override capabilities
    from the bounding set, so the exec'd process does not get them)."""
    if os.geteuid() == 0:
        libc = ctypes.CDLL(None, use_errno=True)
        for cap in (CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH):
            if libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0) != 0:
                raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def _chmod_tree(root: Path, writable: bool) -> None:
    for p in [root, *root.rglob("*")]:
        mode = p.stat().st_mode
        p.chmod(mode | 0o200 if writable else mode & ~0o222)


def _snapshot(root: Path) -> dict[str, tuple[int, int]]:
    """Size and modification time of every file under ``root``."""
    files = (p for p in root.rglob("*") if p.is_file())
    return {str(p): (p.stat().st_size, p.stat().st_mtime_ns) for p in files}


def _one_error_line(stderr: str) -> str:
    errors = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "Traceback" not in stderr, stderr
    return errors[0]


def test_read_only_store(toy_config: Path, tmp_path: Path) -> None:
    args = ["-p", TOY, "-c", str(toy_config), "--local"]
    assert invoke("run", *args).returncode == 0
    root = tmp_path / "data" / "runs" / "store.zarr"
    before = _snapshot(root)
    _chmod_tree(root, writable=False)
    try:
        status = physanim("status", *args[:-1], preexec_fn=_as_plain_user)
        assert status.returncode == 0 and "cached" in status.stdout, status.stderr
        cached = physanim("run", *args, preexec_fn=_as_plain_user)  # nothing to write
        assert cached.returncode == 0, cached.stderr
        edited = physanim("run", *args, "--set", "scale.factor=9", preexec_fn=_as_plain_user)
        assert edited.returncode == 1
        line = _one_error_line(edited.stderr)
        assert f"cannot write {root / TMP}/scale-" in line and "Permission denied" in line
        assert "make the store writable" in line
        debug = physanim("run", *args, "--set", "scale.factor=9", "--debug",
                         preexec_fn=_as_plain_user)  # fmt: skip
        assert debug.returncode == 1 and "Traceback (most recent call last)" in debug.stderr
    finally:
        _chmod_tree(root, writable=True)
    assert _snapshot(root) == before
    assert_store_tells_the_truth(StageStore(root))


def _file_size_limit(limit: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes fail with EFBIG instead

    return apply


def test_full_disk_by_file_size_limit(toy_config: Path, tmp_path: Path) -> None:
    """Writes beyond RLIMIT_FSIZE fail (EFBIG) as on a full disk, without privileges: here
    the last metadata write of the first stage, the one that commits it (its manifest makes
    it the largest file)."""
    args = ["-p", TOY, "-c", str(toy_config), "--local"]
    assert invoke("run", *args).returncode == 0
    root = tmp_path / "data" / "runs" / "store.zarr"
    before = _snapshot(root)
    full = physanim("run", *args, "--set", "source.n_frames=20",
                    preexec_fn=_file_size_limit(1500))  # fmt: skip
    assert full.returncode == 1
    line = _one_error_line(full.stderr)
    assert line.startswith(f"error: no space left writing {root / TMP}/source-")
    assert "(File too large)" in line and "the partial output was discarded" in line
    assert _snapshot(root) == before and list((root / TMP).iterdir()) == []
    debug = physanim("run", *args, "--set", "source.n_frames=20", env=physanim_env(
        PHYSANIM_DEBUG="1"), preexec_fn=_file_size_limit(1500))  # fmt: skip
    assert "Traceback (most recent call last)" in debug.stderr and "File too large" in debug.stderr
    assert_store_tells_the_truth(StageStore(root))
    assert invoke("run", *args, "--set", "source.n_frames=20").returncode == 0


def _can_mount_tmpfs() -> bool:
    if shutil.which("unshare") is None or not sys.platform.startswith("linux"):
        return False
    probe = "mount -t tmpfs -o size=64k tmpfs /mnt 2>/dev/null || mount -t tmpfs tmpfs /tmp"
    test = subprocess.run(["unshare", "-m", "sh", "-c", probe], capture_output=True)
    return test.returncode == 0


@pytest.mark.skipif(not _can_mount_tmpfs(), reason="no private mount namespace for a tmpfs")
def test_full_disk_on_a_small_tmpfs(toy_config: Path, tmp_path: Path) -> None:
    """A real full disk (ENOSPC): the store on a 256 KiB tmpfs in a private mount namespace."""
    disk = tmp_path / "disk"
    disk.mkdir()
    cli = f"{sys.executable} -m cli"
    args = f"-p {TOY} -c {toy_config} --dataset {disk}/ds --local"
    script = f"""
        mount -t tmpfs -o size=256k tmpfs {disk} || exit 99
        cd {ROOT}
        {cli} run {args} --set source.n_frames=100; echo "full rc=$?"
        {cli} verify {args.removesuffix(" --local")}; echo "verify rc=$?"
        echo "tmp: $(ls -A {disk}/ds/runs/store.zarr/.tmp)"
        {cli} run {args} --set source.n_frames=2; echo "small rc=$?"
    """
    out = subprocess.run(["unshare", "-m", "sh", "-c", script], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)  # fmt: skip
    text = out.stdout + out.stderr
    assert "full rc=1" in text and "verify rc=0" in text and "small rc=0" in text, text
    assert "tmp: \n" in out.stdout, text
    line = _one_error_line("\n".join(x for x in text.splitlines() if "no space" in x or
                                     x.startswith(("error:", "Traceback"))))  # fmt: skip
    assert "No space left on device" in line and "the partial output was discarded" in line
