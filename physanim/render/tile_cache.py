"""Rendered tile sequences kept on disk by the content of their inputs (and the renderer's
code), so that a re-run whose meshes did not change does not render them again."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

import physanim.render.face as face
from physanim.store.file_cache import FileCache, content_digest


class TileCache:
    """Rendered tile sequences of uncoloured meshes by the content of their inputs, in
    ``folder`` (.npy); the ``keep`` most recently used stay."""

    def __init__(self, folder: Path, keep: int = 4) -> None:
        self.files = FileCache(folder, keep)

    def render(self, **job: Any) -> np.ndarray:
        """``render_sequence(**job)``, or its earlier result for the same inputs."""
        named = [(name, job[name]) for name in sorted(job) if name != "progress"]
        code = b"".join(f.read_bytes() for f in face.CODE_FILES)  # its code too
        digest = content_digest(code, *(part for pair in named for part in pair))
        cached = self.files.fetch(digest, ".npy")
        if cached is not None:
            try:
                tiles = np.load(cached)
                if job.get("progress") is not None:
                    job["progress"](len(tiles), len(tiles))
                return tiles
            except (OSError, ValueError):
                cached.unlink(missing_ok=True)
        tiles = face.render_sequence(**job)
        self.files.put(digest, ".npy", lambda path: np.save(path, tiles))
        return tiles
