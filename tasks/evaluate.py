"""Stage ``evaluate``: symmetry cost, mouth-corner curves, lag, and how well the simulated face
performs the capture (``physanim.evaluate.face``), against the dataset's ground truth if any;
their plots (``physanim.render.plots.plot_evaluation``) in this output's files/.

Version history: CHANGELOG.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from physanim.evaluate.face import EvaluateParams, FaceEvaluation, FaceRun
from physanim.pipeline import DatasetParams, StageContext, StageOutput, StageSpec
from tasks.align import AlignOutput
from tasks.dense import DenseOutput
from tasks.materials import MaterialsOutput
from tasks.simulate import SimulateOutput
from tasks.tetra import TetraOutput
from tasks.track import TrackOutput

#: What the evaluate stage's files show (a report lists those present), path -> caption.
FILES = {
    "fidelity.png": "Motion fidelity against the truth, per region (0 = moves like the actor)",
    "lip_gap.png": "Lip gap: truth, FEM, kinematic scan",
    "symmetry.png": "Symmetry cost (tracked, kinematic, FEM)",
    "mouth_corners.png": "Mouth-corner displacement",
}


@dataclass(frozen=True)
class EvaluateOutput(FaceEvaluation, StageOutput):
    """Every field of :class:`~physanim.evaluate.face.FaceEvaluation` plus the summary."""


def fingerprint(dataset: DatasetParams, params: EvaluateParams) -> Mapping[str, object]:
    """Size and modification time of every file of the ground truth (an edited truth re-runs
    evaluate)."""
    from physanim.evaluate.truth import truth_fingerprint

    return truth_fingerprint(dataset.path, params.truth)


def face_run(
    track: TrackOutput,
    align: AlignOutput,
    dense: DenseOutput,
    tetra: TetraOutput,
    materials: MaterialsOutput,
    simulate: SimulateOutput,
) -> FaceRun:
    """What the evaluation reads of the upstream outputs (landmark trajectories of the three
    variants in the head frame, the tet mesh and its displacements, the scan)."""
    from physanim.face.drive import head_frame
    from physanim.names import name_index

    names = align.landmark_names
    disp = simulate.displacements.astype(np.float64)
    stabilised = head_frame(track.points, track.head_pose)
    return FaceRun(
        landmark_names=names,
        landmarks=align.landmarks,
        fem_landmarks=tetra.nodes[tetra.landmark_node] + disp[:, tetra.landmark_node],
        kinematic_landmarks=align.motion.astype(np.float64)[:, align.landmark_vertices],
        tracked_landmarks=stabilised[:, name_index(track.landmark_names, names)],
        nodes=tetra.nodes,
        tets=tetra.tets,
        skin=tetra.skin,
        displacements=disp,
        driven=np.union1d(simulate.driven_nodes, simulate.spring_nodes),
        tet_labels=materials.tet_labels,
        scan_labels=materials.scan_labels,
        region_names=materials.region_names,
        mouth=align.mouth(),
        scan_vertices=align.scan_vertices,
        scan_faces=align.scan_faces,
        scan_side=align.scan_side,
        scan_parent=align.scan_parent,
        kinematic=dense.motion,
        times=simulate.times,
        fps=track.fps,
        inverted_count=np.asarray(simulate.inverted_count),
    )


def compute(
    params: EvaluateParams,
    track: TrackOutput,
    align: AlignOutput,
    dense: DenseOutput,
    tetra: TetraOutput,
    materials: MaterialsOutput,
    simulate: SimulateOutput,
    ctx: StageContext[EvaluateParams],
) -> EvaluateOutput:
    """Measures per variant (fem, kinematic, tracked); philtrum peaks; with truth: fidelity,
    lip gap, surface distance and surface quality per frame."""
    from physanim.evaluate.face import evaluate_face
    from physanim.evaluate.truth import load_truth
    from physanim.render.plots import plot_evaluation
    from physanim.store.file_cache import FileCache

    run = face_run(track, align, dense, tetra, materials, simulate)
    path = ctx.dataset_dir / params.truth
    truth = load_truth(path, run.displacements.shape[0]) if path.exists() else None
    # the scan's embedding in the tets and what the truth gives of the capture alone: a
    # material edit reads both back
    cache = FileCache(ctx.dataset.run_dir / "cache" / "embeddings", keep=4)
    evaluation, summary = evaluate_face(run, truth, params, cache)
    plot_evaluation(simulate.times, evaluation, ctx.files_dir)
    measures = {f.name: getattr(evaluation, f.name) for f in fields(evaluation)}
    return EvaluateOutput(**measures, summary=summary)


SPEC = StageSpec.typed(
    "evaluate",
    compute,
    version="19",
    doc="symmetry cost, mouth corners, lags (free behind driven, FEM behind capture per "
    "region), philtrum peaks; with truth: motion fidelity per "
    "region, lip gap, surface distance, silhouettes and triangle stretch of the moved scan",
    fingerprint=fingerprint,
    files=FILES,
)
