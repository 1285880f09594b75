"""Stage ``actuate``: the inverse step, the tissue's active stress that performs the capture.

Per capture frame, the actuation (active stress over smooth patches of the tissue,
``physanim.fem.actuation``) with which the static FEM at a fixed basis material
(``simulate.actuation.basis_material``; never the ``materials`` stage's output, so a material
edit never runs this stage again) moves the free skin as captured, with the skull held and
the mandible turned as the ``simulate`` drive does (``physanim.fem.inverse``), each skin
node weighted by its skin area and the capture's confidence there. The stage reads
the ``simulate`` section (its model, ``jaw`` and ``actuation`` settings), so the inverse step
and the FEM run share them; ``simulate.drive.mode: actuation`` runs the edited material with
this actuation held; under any other drive the stage stores an empty actuation at once (the
drive's mode is in its key). The captured motion is read in one place, :func:`captured_motion`.
Version history: CHANGELOG.md.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from physanim.face.params import ActuationParams, DriveParams, JawParams
from physanim.fem.params import ModelParams
from physanim.pipeline import StageContext, StageOutput, StageSpec
from tasks.align import AlignOutput
from tasks.dense import DenseOutput
from tasks.tetra import TetraOutput
from tasks.track import TrackOutput

if TYPE_CHECKING:
    from physanim.face.drive import FaceDrive
    from physanim.fem.actuation import Actuation, StressBasis
    from physanim.fem.boundary import BoundaryConditions
    from physanim.fem.inverse import ActuationFit
    from physanim.fem.model import FemModel


class DriveMode(BaseModel):
    """Of ``simulate.drive``, what the inverse step needs: whether the drive uses it, and the
    landmark patches it also fits (only these enter the key, so no other drive setting runs
    the inverse step again)."""

    model_config = ConfigDict(extra="ignore")
    mode: str = Field(
        DriveParams.model_fields["mode"].default,
        description="simulate's drive; the inverse step runs only for 'actuation' (any other "
        "mode stores an empty actuation at once)",
    )
    landmarks: list[str] | None = DriveParams.model_fields["landmarks"]
    exclude: list[str] = DriveParams.model_fields["exclude"]
    radius_m: float = DriveParams.model_fields["radius_m"]

    def patches(self) -> DriveParams:
        """The landmark-spring drive of these landmarks and patches (its patches and targets
        are what the inverse step reads)."""
        return DriveParams(
            mode="landmarks", landmarks=self.landmarks, exclude=self.exclude,
            radius_m=self.radius_m,
        )  # fmt: skip


class ActuateParams(ModelParams):
    """The inverse step's settings, from the ``simulate`` section: the FEM model's (element,
    law, solver), the drive's mode, the mandible's motion and the fit's."""

    model_config = ConfigDict(extra="forbid")
    drive: DriveMode = Field(default_factory=DriveMode, description="simulate's drive (its mode)")
    jaw: JawParams = Field(default_factory=JawParams, description="mandible motion")
    actuation: ActuationParams = Field(
        default_factory=ActuationParams, description="the inverse step (stage 'actuate')"
    )


@dataclass(frozen=True)
class ActuateOutput(StageOutput):
    """The fitted actuation of T frames over P patches: ``coefficients`` (T, P, 5) Pa of the
    deviatoric stress directions (``physanim.fem.actuation.DEVIATORIC``) of the patches
    centred at ``centres`` (P, 3) m reaching ``radius_m`` m, lifted along the patches' fourth
    axis by ``centre_lift`` (P,) m (the tets by ``lip_lift_m`` m times their lip side,
    ``physanim.fem.actuation.seam_lift``; 0: no lip patches); ``patch_region`` (P,) int8 index
    of each centre's face region into ``regions`` (-1: none); ``skin_nodes`` (S,) the free
    skin nodes fitted; ``residual`` (T,) and ``residual_regions`` (T, len(regions)) the static
    fit's relative displacement error against the captured motion (NaN: nothing moves over
    1 mm), ``passive`` (T,) the same for the mandible alone (no actuation)."""

    coefficients: np.ndarray
    centres: np.ndarray
    centre_lift: np.ndarray
    patch_region: np.ndarray
    skin_nodes: np.ndarray
    residual: np.ndarray
    residual_regions: np.ndarray
    passive: np.ndarray
    regions: list[str] = field(default_factory=list)
    radius_m: float = 0.0
    lip_lift_m: float = 0.0

    def actuation(
        self, tetra: TetraOutput, drive: DriveParams, activity: np.ndarray | None = None
    ) -> Actuation:
        """The actuation over tetra's mesh with each patch's coefficients times its region's
        ``drive.actuation_scale``, in every frame or weighted by the gesture's ``activity``
        (T,) in [0, 1] (``physanim.face.gesture``)."""
        from physanim.evaluate.fidelity import region_names
        from physanim.face.gesture import gesture_factors
        from physanim.fem.actuation import Actuation, StressBasis, seam_lift

        lift = seam_lift(tetra.tets, tetra.side, self.lip_lift_m)
        basis = StressBasis.patches(
            tetra.nodes, tetra.tets, self.centres, self.radius_m, lift, self.centre_lift
        )
        names = region_names(self.patch_region, self.regions)
        factors = np.array([drive.scale_of(n) for n in names])
        return Actuation(basis, self.coefficients).scaled(gesture_factors(factors, activity))


def captured_motion(dense: DenseOutput) -> tuple[np.ndarray, np.ndarray]:
    """The captured skin motion the inverse step fits: per-vertex positions (T, V, 3) m in
    the head frame on the vertices of align's scan, and their confidence (T, V) in [0, 1]:
    the ``dense`` stage's captured scan (dense capture, or the kinematic scan with
    ``dense.method: kinematic``)."""
    return np.asarray(dense.motion[...]), np.asarray(dense.confidence, dtype=np.float64)


def stage_drive(
    track: TrackOutput,
    align: AlignOutput,
    tetra: TetraOutput,
    drive: DriveParams,
    jaw: JawParams,
) -> FaceDrive:
    """The face drive (``physanim.face.performance``) of the track, align and tetra outputs."""
    from physanim.face.performance import landmark_motion, performance_drive
    from physanim.names import name_index

    pronasale = align.landmarks[name_index(align.landmark_names, ["pronasale"])[0]]
    tissue = {k: getattr(tetra, k) for k in ("nodes", "tets", "skin", "bone", "side")}
    return performance_drive(
        track.landmark_names, track.template, landmark_motion(track.points, track.head_pose),
        align.mouth(), pronasale, align.motion, {**tissue, "skin_anchor": tetra.skin_anchor},
        (align.scan_vertices, align.scan_faces), lambda: align.kinematic[...], drive, jaw,
    )  # fmt: skip


def with_landmarks(
    params: ActuateParams,
    landmarks: FaceDrive,
    nodes: np.ndarray,
    targets: np.ndarray,
    weights: np.ndarray,
    areas: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The observed nodes (S,), targets (T, S, 3) m and weights (T, S) of the captured scan
    with the skin nodes of the landmark patches of ``landmarks`` (a landmark-spring drive)
    appended, each towards its landmark's motion with weight ``landmark_weight`` times its
    skin area ``areas`` (N,) m^2 (a node may appear twice: two rows of the fit)."""
    springs, factor = landmarks.springs, params.actuation.landmark_weight
    if springs is None:
        return nodes, targets, weights
    extra = np.broadcast_to(factor * areas[springs.nodes], (len(weights), len(springs.nodes)))
    return (
        np.r_[nodes, springs.nodes],
        np.concatenate([targets, springs.targets], axis=1),
        np.concatenate([weights, extra], axis=1),
    )


@dataclass(frozen=True)
class FitInputs:
    """What the inverse step fits: the ``conditions`` (skull held, mandible turned), the
    ``observed`` (S,) nodes (the captured scan's skin nodes first, ``n_captured`` of them,
    then any landmark patches' nodes), their ``targets`` (T, S, 3) m and ``weights`` (T, S)."""

    conditions: BoundaryConditions
    observed: np.ndarray
    targets: np.ndarray
    weights: np.ndarray
    n_captured: int


def fit_inputs(
    params: ActuateParams,
    track: TrackOutput,
    align: AlignOutput,
    dense: DenseOutput,
    tetra: TetraOutput,
) -> FitInputs:
    """The inverse step's conditions, observed nodes, targets and weights: each skin node
    bound to the captured scan towards its motion, weighted by its skin area and the
    capture's confidence there (``filled_weight`` where the capture filled it in)."""
    from physanim.face.drive import skin_areas
    from physanim.face.performance import SkinBinding
    from physanim.fem.boundary import BoundaryConditions

    nodes = tetra.nodes
    drive = stage_drive(track, align, tetra, DriveParams(mode="actuation"), params.jaw)
    conditions = BoundaryConditions.checked(
        len(nodes), drive.prescribed, drive.prescribed_traj, 1.0 / float(track.fps)
    )
    tissue = {k: getattr(tetra, k) for k in ("nodes", "skin", "bone", "side")}
    binding = SkinBinding.of(tissue, align.mouth(), (align.scan_vertices, align.scan_faces))
    motion, confidence = captured_motion(dense)
    targets = binding.displacements(motion)
    fill = params.actuation.filled_weight
    trust = fill + (1.0 - fill) * binding.values(confidence)
    areas = skin_areas(nodes, tetra.tets, tetra.skin)
    weights = areas[binding.nodes] * trust
    observed = binding.nodes
    if params.actuation.landmark_weight > 0:  # the landmark drive (a second jaw estimate)
        observed, targets, weights = with_landmarks(
            params, stage_drive(track, align, tetra, params.drive.patches(), params.jaw),
            observed, targets, weights, areas,
        )  # fmt: skip
    return FitInputs(conditions, observed, targets, weights, len(binding.nodes))


def compute(
    params: ActuateParams,
    track: TrackOutput,
    align: AlignOutput,
    dense: DenseOutput,
    tetra: TetraOutput,
    ctx: StageContext[ActuateParams],
) -> ActuateOutput:
    """Coefficients (T, P, 5) Pa, patch centres (P, 3) m and regions, the fit's relative
    residual per frame (T,) and face region (T, R)."""
    from physanim.evaluate.fidelity import REGIONS, face_regions, motion_fidelity

    if params.drive.mode != "actuation":
        return _not_needed(len(track.points), params.drive.mode)
    report = ctx.progress("actuate")
    report(0, 2)
    t_start = t0 = time.perf_counter()
    inputs = fit_inputs(params, track, align, dense, tetra)
    observed, targets, weights = inputs.observed, inputs.targets, inputs.weights
    t_drive = time.perf_counter() - t0
    report(1, 2)
    landmarks = align.landmark_positions()
    step = inverse_step(params, tetra, inputs.conditions, observed, targets, weights, landmarks)
    fit, basis = step.fit, step.basis
    report(2, 2)

    n = inputs.n_captured  # the residual on the captured scan's rows (no landmark rows)
    labels = face_regions(tetra.nodes[observed[:n]], landmarks)
    captured, fitted = targets[:, :n], fit.fitted[:, :n]
    residual = motion_fidelity(fitted, captured, labels)
    passive = motion_fidelity(fit.passive[:, :n], captured, labels).overall
    seconds = {"drive": t_drive, "model": step.model_seconds, **fit.seconds}
    seconds["total"] = time.perf_counter() - t_start
    summary = _summary(fitted, captured, weights[:, :n], residual, passive, seconds, fit)
    summary.update(patches=basis.n_patches, skin_nodes=n)
    return ActuateOutput(
        coefficients=fit.coefficients,
        centres=basis.centres,
        centre_lift=basis.lift,
        patch_region=step.patch_region,
        skin_nodes=observed[:n],
        residual=residual.overall,
        residual_regions=residual.regions,
        passive=passive,
        regions=list(REGIONS),
        radius_m=basis.radius,
        lip_lift_m=lip_lift(params),
        summary=summary,
    )


@dataclass(frozen=True)
class InverseStep:
    """The inverse step's answer: the ``fit``; the ``model`` (the basis material) and stress
    ``basis`` it was fitted with; each patch's face region index ``patch_region`` (P,) (-1:
    none) and stress cost factor ``patch_cost`` (P,); the seconds spent building the model
    and the basis."""

    fit: ActuationFit
    model: FemModel
    basis: StressBasis
    patch_region: np.ndarray
    patch_cost: np.ndarray
    model_seconds: float


def inverse_step(
    params: ActuateParams,
    tetra: TetraOutput,
    conditions: BoundaryConditions,
    observed: np.ndarray,
    targets: np.ndarray,
    weights: np.ndarray,
    landmarks: dict[str, np.ndarray],
) -> InverseStep:
    """The fitted actuation (``physanim.fem.inverse.fit_actuation``) of the tetra mesh at the
    basis material under ``conditions``, moving the ``observed`` (S,) skin nodes to
    ``targets`` (T, S, 3) m with ``weights`` (T, S), each patch at the stress cost of its
    face region (from the feature points ``landmarks``, m) and depth under the skin."""
    from scipy.spatial import cKDTree

    from physanim.evaluate.fidelity import face_regions, region_names
    from physanim.fem.actuation import StressBasis, seam_lift
    from physanim.fem.inverse import fit_actuation
    from physanim.fem.materials import TetMaterials
    from physanim.fem.model import build_model

    t0 = time.perf_counter()
    fit_params, m = params.actuation, params.actuation.basis_material
    materials = TetMaterials.uniform(
        len(tetra.tets), E=m.E_kPa * 1e3, nu=m.nu, eta=m.eta_Pa_s, rho=m.rho_kg_m3, **m.fields
    )
    model = build_model(tetra.nodes, tetra.tets, materials, params)
    lift = seam_lift(tetra.tets, tetra.side, lip_lift(params))
    skin = cKDTree(tetra.nodes[tetra.skin])
    # patch centres where the facial muscles lie, unless the deep tissue may hold them too
    centroids = tetra.nodes[tetra.tets].mean(axis=1)
    muscle = (
        None if fit_params.deep_centres else skin.query(centroids)[0] <= fit_params.deep_below_m
    )
    basis = StressBasis.covering(tetra.nodes, tetra.tets, fit_params.patch_spacing_m, lift, muscle)
    patch_region = face_regions(basis.centres, landmarks)
    depth = skin.query(basis.centres)[0]
    cost = np.asarray(fit_params.patch_cost(region_names(patch_region), depth))
    t_model = time.perf_counter() - t0
    fit = fit_actuation(
        model, basis, conditions, observed, targets, weights,
        fit_params.stress_cost_mm_per_kPa * 1e-6, fit_params.rate_cost_mm_per_kPa * 1e-6,
        params.solver, fit_params.robust_mm * 1e-3, cost,
    )  # fmt: skip
    return InverseStep(fit, model, basis, patch_region, cost, t_model)


def lip_lift(params: ActuateParams) -> float:
    """The lip tets' offset along the patches' fourth axis, m (0 without lip patches)."""
    from physanim.fem.actuation import SEAM_LIFT_PER_SPACING

    fit = params.actuation
    return SEAM_LIFT_PER_SPACING * fit.patch_spacing_m if fit.lip_patches else 0.0


def _not_needed(n_frames: int, mode: str) -> ActuateOutput:
    """The empty actuation of ``n_frames`` frames that a drive other than 'actuation' reads
    (it applies none): the inverse step costs nothing where it is not used."""
    from physanim.evaluate.fidelity import REGIONS

    nothing = np.full(n_frames, np.nan)
    return ActuateOutput(
        coefficients=np.zeros((n_frames, 0, 5)),
        centres=np.zeros((0, 3)),
        centre_lift=np.zeros(0),
        patch_region=np.zeros(0, np.int8),
        skin_nodes=np.zeros(0, np.int64),
        residual=nothing,
        residual_regions=np.full((n_frames, len(REGIONS)), np.nan),
        passive=nothing,
        regions=list(REGIONS),
        summary={
            "inverse_step": f"not run: simulate.drive.mode is {mode!r}; it runs for 'actuation'"
        },
    )


def _summary(
    fitted: np.ndarray, targets: np.ndarray, weights: np.ndarray, residual: Any,
    passive: np.ndarray, seconds: dict[str, float], fit: Any,
) -> dict[str, Any]:  # fmt: skip
    """The stage summary: the fit's relative residual overall and per region at the frame of
    the largest captured motion and at its worst frame, the weighted RMS misfit (mm), the
    peak active stress (kPa), iterations and seconds."""
    from physanim.evaluate.fidelity import REGIONS

    def r(x: float) -> float | None:
        return None if not np.isfinite(x) else round(float(x), 4)

    moved = np.sqrt(np.einsum("ts,tsc->t", weights, targets**2) / weights.sum(axis=1))
    misfit = np.einsum("ts,tsc->t", weights, (fitted - targets) ** 2) / weights.sum(axis=1)
    peak = int(moved.argmax())
    worst = int(np.nanargmax(residual.overall)) if np.isfinite(residual.overall).any() else None
    return {
        "peak_motion_frame": peak,
        "residual_at_peak_motion": {
            "overall": r(residual.overall[peak]),
            "passive": r(passive[peak]),
            **{name: r(residual.regions[peak, i]) for i, name in enumerate(REGIONS)},
        },
        "residual_worst_frame": worst,
        "residual_worst": None if worst is None else r(residual.overall[worst]),
        "misfit_rms_mm": round(float(np.sqrt(misfit.mean())) * 1e3, 4),
        "motion_rms_mm": round(float(np.sqrt((moved**2).mean())) * 1e3, 4),
        "peak_active_stress_kPa": round(
            float(np.linalg.norm(fit.coefficients, axis=2).max()) * 1e-3, 3
        ),
        "cg_iterations": fit.iterations,
        "seconds": {k: round(v, 3) for k, v in seconds.items()},
    }


SPEC = StageSpec.typed(
    "actuate",
    compute,
    version="3",
    doc="inverse step: per-frame active stress with which the FEM at a fixed basis material "
    "reproduces the captured skin motion (simulate's jaw, model and actuation settings)",
    section="simulate",
)
