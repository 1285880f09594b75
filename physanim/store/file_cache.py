"""Outputs kept on disk by the content of what made them, so that a re-run whose inputs did
not change reads them back instead of making them again (rendered tiles, figures that a
material edit does not change). Not part of the stage store: losing the cache costs time only.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def content_digest(*parts: Any) -> str:
    """sha256 (hex) of ``parts``: arrays by dtype, shape and bytes, bytes as they are, anything
    else by its repr (so dicts, tuples and numbers by value)."""
    digest = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            digest.update(f"{part.dtype}{part.shape}".encode())
            digest.update(np.ascontiguousarray(part).tobytes())
        elif isinstance(part, bytes):
            digest.update(part)
        else:
            digest.update(repr(part).encode())
        digest.update(b"\x00")
    return digest.hexdigest()


class FileCache:
    """Files by content digest in ``folder``; the ``keep`` most recently used stay."""

    def __init__(self, folder: Path, keep: int = 16) -> None:
        self.folder, self.keep = Path(folder), keep

    def path(self, digest: str, suffix: str) -> Path:
        return self.folder / f"{digest[:32]}{suffix}"

    def fetch(self, digest: str, suffix: str) -> Path | None:
        """The cached file of ``digest`` (marked as just used), or None."""
        found = self.path(digest, suffix)
        if not found.exists():
            return None
        found.touch()
        return found

    def put(self, digest: str, suffix: str, write: Callable[[Path], Any]) -> Path:
        """The file of ``digest``, written by ``write(path)`` aside and then renamed (a crash
        never leaves half a file); the least recently used beyond ``keep`` go."""
        target = self.path(digest, suffix)
        self.folder.mkdir(parents=True, exist_ok=True)
        # one aside-file per process and thread: stages in threads of one run (evaluate and
        # export embed the same scan) may put the same digest at once
        tmp = target.with_name(f".{target.stem}.{os.getpid()}.{threading.get_ident()}{suffix}")
        write(tmp)
        tmp.replace(target)
        kept = sorted((t, p) for p in self.folder.iterdir() if (t := _mtime(p)) is not None)
        for _, old in kept[: -self.keep]:
            old.unlink(missing_ok=True)
        return target

    def make(self, out: Path, digest: str, producer: Callable[[Path], Any]) -> Path:
        """``out`` linked from the cache when ``digest`` is there (:func:`share`), else made
        by ``producer(out)`` and kept."""
        cached = self.fetch(digest, out.suffix)
        if cached is not None:
            share(cached, out)
            return out
        producer(out)
        self.put(digest, out.suffix, lambda tmp: share(out, tmp))
        return out


def share(source: Path, target: Path) -> None:
    """``target`` as a hard link to ``source`` (one file on disk: a material edit's outputs
    share the unchanged capture's 50 MB files instead of copying them), or a copy where the
    file system cannot link them (another device, no hard links). Both must stay read-only:
    the cache and the store's outputs are never written in place."""
    target.unlink(missing_ok=True)
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def _mtime(path: Path) -> float | None:
    """The modification time of a cached file (not an aside-file), None for an aside-file or
    one another thread or process removed meanwhile."""
    if path.name.startswith("."):
        return None
    try:
        return path.stat().st_mtime if path.is_file() else None
    except FileNotFoundError:
        return None
