"""Every file of one mesh animation, and how faithful the compressed one is."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from physanim.export.animation import MeshAnimation
from physanim.export.params import ExportParams
from physanim.store.file_cache import FileCache, content_digest, share

#: The modules whose code makes the files: an edit of any of them makes them anew.
_WRITERS = ("files.py", "animation.py", "usd.py", "gltf.py", "alembic.py", "blender_scene.py")


@dataclass(frozen=True)
class ExportedFiles:
    """What :func:`export_files` wrote for one animation: the ``usd``, ``glb`` and (or None)
    ``abc`` paths; the glTF's ``targets`` (count), and the distance of its decoded animation
    from the full one over frames and vertices, ``rms_mm`` and ``max_mm``; ``normal_p99_deg``
    the 99th percentile of the angle between its morphed normals and the frames' normals."""

    usd: Path
    glb: Path
    abc: Path | None
    targets: int
    rms_mm: float
    max_mm: float
    normal_p99_deg: float

    def summary(self) -> dict[str, Any]:
        """JSON-able facts: file sizes (MB) and the glTF's fidelity."""
        sizes = {p.suffix[1:] + "_mb": round(p.stat().st_size / 1e6, 3) for p in self.paths}
        return {
            **sizes,
            "gltf_targets": self.targets,
            "gltf_rms_mm": round(self.rms_mm, 5),
            "gltf_max_mm": round(self.max_mm, 4),
            "gltf_normal_p99_deg": round(self.normal_p99_deg, 2),
            "gltf_size_of_usd": round(self.glb.stat().st_size / self.usd.stat().st_size, 4),
        }

    @property
    def paths(self) -> list[Path]:
        """The files written, USD first."""
        return [p for p in (self.usd, self.glb, self.abc) if p is not None]


def export_files(
    animation: MeshAnimation, folder: Path, params: ExportParams, doc: str = ""
) -> ExportedFiles:
    """``folder/<name>.usdc``, ``<name>.glb`` and (``params.alembic``) ``<name>.abc`` of
    ``animation`` (``doc``: a line on what it shows, kept in the USD and glTF); the glTF is
    read back to measure its fidelity."""
    from physanim.export.alembic import write_alembic
    from physanim.export.gltf import morph_animation, read_glb, rms_distance, write_glb
    from physanim.export.usd import write_usd

    name = animation.name
    usd = write_usd(animation, folder / f"{name}.usdc", doc)
    morph = morph_animation(
        animation, params.gltf_tolerance_mm * 1e-3, params.gltf_max_targets,
        params.gltf_quantized,
    )  # fmt: skip
    extras = {"description": doc, "fps": animation.fps, "frames": animation.frames}
    glb = write_glb(morph, animation.faces, folder / f"{name}.glb", name, extras)
    decoded = read_glb(glb)
    positions = decoded.positions()
    error = positions - animation.points
    cosine = np.einsum("tni,tni->tn", decoded.normals(), animation.normals)
    abc = None
    if params.alembic:
        abc = write_alembic(usd, folder / f"{name}.abc", animation.fps, animation.frames)
    return ExportedFiles(
        usd, glb, abc, len(decoded.targets),
        rms_mm=rms_distance(positions, animation.points) * 1e3,
        max_mm=float(np.sqrt(np.einsum("tni,tni->tn", error, error).max())) * 1e3,
        normal_p99_deg=float(np.degrees(np.arccos(np.clip(np.percentile(cosine, 1), -1, 1)))),
    )  # fmt: skip


def cached_export_files(
    animation: MeshAnimation, folder: Path, params: ExportParams, doc: str, cache: FileCache
) -> ExportedFiles:
    """:func:`export_files`, or its files linked from ``cache`` when the same animation,
    settings and writers made them before (a material edit re-exports the FEM skin, not the
    unchanged captured motion: 3-4 s of the stage on the demo; and its variants share the
    capture's files on disk, 55 MB each, instead of holding copies)."""
    here = Path(__file__).parent
    digest = content_digest(
        *(here.joinpath(m).read_bytes() for m in _WRITERS), animation.name, animation.points,
        animation.faces, animation.fps, params.model_dump(), doc,
    )  # fmt: skip
    suffixes = [".usdc", ".glb", *([".abc"] if params.alembic else [])]
    facts = cache.fetch(digest, ".json")
    found = [cache.fetch(digest, s) for s in suffixes]
    name = animation.name
    if facts is not None and all(f is not None for f in found):
        for cached, suffix in zip(found, suffixes, strict=True):
            share(cached, folder / f"{name}{suffix}")
        known = json.loads(facts.read_text())
        paths = [folder / f"{name}{s}" for s in suffixes]
        return ExportedFiles(paths[0], paths[1], paths[2] if params.alembic else None, **known)
    made = export_files(animation, folder, params, doc)
    for path in made.paths:
        cache.put(digest, path.suffix, lambda tmp, path=path: share(path, tmp))
    known = dict(
        targets=made.targets, rms_mm=made.rms_mm, max_mm=made.max_mm,
        normal_p99_deg=made.normal_p99_deg,
    )  # fmt: skip
    cache.put(digest, ".json", lambda tmp: tmp.write_text(json.dumps(known)))
    return made
