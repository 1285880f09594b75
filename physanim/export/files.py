"""Every file of one mesh animation, and how faithful the compressed one is."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from physanim.export.animation import MeshAnimation
from physanim.export.params import ExportParams


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
