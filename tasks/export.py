"""Stage ``export``: the simulated skin and the captured motion as files for Blender, Maya,
Houdini, Unreal or a web page.

Two variants of the high-res scan moving at the capture frame rate, in the actor frame
(metres, +y up, +z out of the face): ``fem``, the scan embedded in the tets and moved by the
FEM (the render's FEM tiles, ``physanim.mesh.embed``), and ``capture``, the captured scan
(stage ``dense``: dense capture, or the kinematic scan with ``dense.method: kinematic``), as
the report shows them. Each becomes a USD stage with point time samples
(``<variant>.usdc``), a glTF binary with a morph-target basis (``<variant>.glb``) and, with
``export.alembic``, an Alembic file written by Blender (``<variant>.abc``), in this output's
files/ (``physanim show export`` prints where). A variant whose motion, settings and writers
are those of an earlier export (the capture, after a material edit) has its files copied from
the run directory's ``cache/export`` instead of written again. Version history: CHANGELOG.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from physanim.export.params import ExportParams
from physanim.pipeline import StageContext, StageOutput, StageSpec
from tasks.align import AlignOutput
from tasks.dense import DenseOutput
from tasks.simulate import SimulateOutput
from tasks.tetra import TetraOutput
from tasks.track import TrackOutput

#: What each variant shows, kept in its files.
VARIANTS = {
    "fem": "physanim: the scanned skin moved by the FEM simulation",
    "capture": "physanim: the scanned skin moved by the captured motion (stage dense)",
}


@dataclass(frozen=True)
class ExportOutput(StageOutput):
    """Per variant (``variants``, in order): ``files`` written in files/ (USD, glTF[, Alembic]),
    the glTF's morph ``gltf_targets`` and the distance of its decoded animation from the full
    one over frames and vertices, ``gltf_rms_mm`` and ``gltf_max_mm``; ``frames`` at ``fps``
    frames/s, ``vertices`` of the scan."""

    variants: list[str] = field(default_factory=list)
    files: list[str] = field(default_factory=list)
    gltf_targets: list[int] = field(default_factory=list)
    gltf_rms_mm: list[float] = field(default_factory=list)
    gltf_max_mm: list[float] = field(default_factory=list)
    frames: int = 0
    fps: float = 0.0
    vertices: int = 0


def compute(
    params: ExportParams,
    track: TrackOutput,
    align: AlignOutput,
    dense: DenseOutput,
    tetra: TetraOutput,
    simulate: SimulateOutput,
    ctx: StageContext[ExportParams],
) -> ExportOutput:
    """USD, glTF (and Alembic) files of the FEM skin and of the captured scan."""
    from physanim.export import require
    from physanim.export.animation import MeshAnimation
    from physanim.export.files import cached_export_files
    from physanim.mesh.embed import embedded_displacements
    from physanim.store.file_cache import FileCache

    require("pxr", "pygltflib")  # before any writing
    if params.alembic:
        from physanim.export.blender import require_blender

        require_blender()
    scan = align.scan_vertices
    fem_skin = scan + embedded_displacements(
        scan, align.scan_side, tetra.nodes, tetra.tets, align.mouth(), simulate.displacements,
        FileCache(ctx.dataset.run_dir / "cache" / "embeddings", keep=4),
    )  # fmt: skip
    motion = {"fem": fem_skin, "capture": dense.motion}
    progress = ctx.progress("export")
    # the files by their content: a material edit writes the FEM's anew, copies the capture's
    files = FileCache(ctx.dataset.run_dir / "cache" / "export", keep=4 * (3 + params.alembic))
    written = {}
    for i, (name, doc) in enumerate(VARIANTS.items()):
        progress(i, len(VARIANTS))
        animation = MeshAnimation(name, motion[name][...], align.scan_faces, float(track.fps))
        written[name] = cached_export_files(animation, ctx.files_dir, params, doc, files)
    progress(len(VARIANTS), len(VARIANTS))
    warnings = [
        f"{w.glb.name}: {w.rms_mm:.3f} mm RMS from the full animation with "
        f"{params.gltf_max_targets} morph targets, over export.gltf_tolerance_mm "
        f"{params.gltf_tolerance_mm}: raise export.gltf_max_targets"
        for w in written.values()
        if w.rms_mm > params.gltf_tolerance_mm
    ]
    return ExportOutput(
        variants=list(written),
        files=[p.name for w in written.values() for p in w.paths],
        gltf_targets=[w.targets for w in written.values()],
        gltf_rms_mm=[w.rms_mm for w in written.values()],
        gltf_max_mm=[w.max_mm for w in written.values()],
        frames=animation.frames,
        fps=animation.fps,
        vertices=animation.vertices,
        summary={name: w.summary() for name, w in written.items()}
        | ({"warnings": warnings} if warnings else {}),
    )


SPEC = StageSpec.typed(
    "export",
    compute,
    version="3",
    doc="USD, glTF (morph targets) and optional Alembic files of the FEM skin and the capture",
)
