"""Rendered tile sequences kept on disk by the content of their inputs (and the renderer's
code), so that a re-run whose meshes did not change does not render them again."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

import numpy as np

import physanim.render.face as face


class TileCache:
    """Rendered tile sequences of uncoloured meshes by the content of their inputs, in
    ``folder`` (.npy); the ``keep`` most recently used stay."""

    def __init__(self, folder: Path, keep: int = 4) -> None:
        self.folder, self.keep = folder, keep

    def render(self, **job: Any) -> np.ndarray:
        """``render_sequence(**job)``, or its earlier result for the same inputs."""
        digest = hashlib.sha256(b"".join(f.read_bytes() for f in face.CODE_FILES))  # its code too
        for name in sorted(job):
            if name != "progress":
                value = job[name]
                data = value.tobytes() if isinstance(value, np.ndarray) else repr(value).encode()
                digest.update(name.encode() + b"=" + data)
        path = self.folder / f"{digest.hexdigest()[:32]}.npy"
        if path.exists():
            try:
                tiles = np.load(path)
                path.touch()
                if job.get("progress") is not None:
                    job["progress"](len(tiles), len(tiles))
                return tiles
            except (OSError, ValueError):
                path.unlink(missing_ok=True)
        tiles = face.render_sequence(**job)
        self.folder.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.stem}.{os.getpid()}.npy")
        np.save(tmp, tiles)
        tmp.replace(path)
        for old in sorted(self.folder.glob("*.npy"), key=lambda p: p.stat().st_mtime)[: -self.keep]:
            old.unlink(missing_ok=True)
        return tiles
