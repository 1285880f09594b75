"""How a simulated face performs the capture: the evaluate stage's computation.

Per variant (FEM skin at the landmark nodes, kinematic motion mesh, tracked landmarks with the
head pose removed): the seed's symmetry cost and displacement curves; the lag of the free skin
behind the driven nodes; the lag of the FEM skin behind the captured scan per facial region
(fractions of a frame: a more viscous region trails by about its Kelvin-Voigt time eta / E);
the philtrum regions' peak displacement; and, with a ground truth
(``physanim.evaluate.truth``), the motion fidelity per frame and facial region, the lip gap
and the RMS point-to-surface distance of the FEM skin and of the kinematic scan, each on one
sample of the scan's vertices (moved by the FEM through their embedding in the tets, and by the
capture), the same points whatever the tet mesh: those on the true surface (a scan vertex in
a hole of the actor's range scan, which the scan stage filled, has no truth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import BaseModel, ConfigDict, Field

from physanim.evaluate.fidelity import TRUTH_MAX_DISTANCE_M, Fidelity
from physanim.evaluate.measures import LandmarkMeasures
from physanim.evaluate.surfaces import SurfaceQuality
from physanim.evaluate.truth import Truth
from physanim.mesh.seam import MouthLine
from physanim.store.file_cache import FileCache


class EvaluateParams(BaseModel):
    """Evaluation settings."""

    model_config = ConfigDict(extra="forbid")
    truth: str = Field("ground_truth.zarr", description="ground truth in the dataset, if any")
    error_every_frames: int = Field(
        10,
        ge=1,
        le=1000,
        description="frame stride of the surface distance to the truth (10: the demo's RMS "
        "within 0.05 % of every frame's, at a tenth of the closest-point searches)",
    )
    error_max_points: int = Field(4000, ge=100, le=10**6, description="scan points sampled")
    max_lag_frames: int = Field(15, ge=1, le=300, description="search range of the lag, frames")
    min_motion_m: float = Field(
        1e-3,
        gt=0.0,
        le=0.05,
        description="fidelity counts points whose true motion exceeds this, m",
    )
    truth_max_distance_m: float = Field(
        TRUTH_MAX_DISTANCE_M,
        gt=0.0,
        le=0.05,
        description="scan points farther than this from the true neutral surface have no "
        "truth and are left out of the truth's figures, m (the scan's filled holes where the "
        "actor's range scan has none: on the demo 1,640 of 24,447 vertices, up to 8 mm off, "
        "under the nose and in the chin's crack; elsewhere the scan lies within 0.76 mm)",
    )
    closest_points: Literal["bvh", "grid"] = Field(
        "bvh",
        description="closest-point search against the truth: bvh (Open3D, float32 search, "
        "20x faster) or grid (the seed's exact search; the reference, same figures to 1e-6)",
    )
    lip_offset_m: float = Field(
        0.003, gt=0.0, le=0.02, description="lip midline points this far above / below the mouth, m"
    )
    silhouette_views_deg: tuple[float, ...] = Field(
        (0.0, 70.0),
        min_length=1,
        max_length=8,
        description="azimuths of the cameras whose silhouettes of the moved scan are compared "
        "with the truth's, degrees (0: the panel's frontal tile; 70: its side tiles, as "
        "render.side_view_deg)",
    )
    silhouette_size_px: tuple[int, int] = Field(
        (240, 320), description="width and height of those silhouettes, pixels"
    )


@dataclass(frozen=True)
class FaceRun:
    """What the evaluation reads of one run (T frames, L landmarks, n nodes, N scan vertices).

    ``landmark_names`` (L) and ``landmarks`` (L, 3) m the feature points on the scan;
    ``fem_landmarks``, ``kinematic_landmarks``, ``tracked_landmarks`` (T, L, 3) m the three
    variants' landmark trajectories (head frame); ``nodes`` (n, 3) m, ``tets`` (m, 4),
    ``skin`` (n,) bool, ``displacements`` (T, n, 3) m; ``driven`` the node ids the drive
    holds; ``tet_labels`` (m,) and ``scan_labels`` (N,) into ``region_names``; ``mouth`` the
    lip seam;
    ``scan_vertices`` (N, 3) m, ``scan_faces`` (F, 3), ``scan_side`` (N,), ``scan_parent``
    (N,) the uncut vertex of each, ``kinematic`` (T, N, 3) m (a Zarr array or numpy array,
    read by rows); ``times`` (T,) s of the frames; ``fps`` frames/s; ``inverted_count`` (T,)
    how many tets the simulation turned inside out in each frame.
    """

    landmark_names: list[str]
    landmarks: NDArray
    fem_landmarks: NDArray
    kinematic_landmarks: NDArray
    tracked_landmarks: NDArray
    nodes: NDArray
    tets: NDArray
    skin: NDArray
    displacements: NDArray
    driven: NDArray
    tet_labels: NDArray
    scan_labels: NDArray
    region_names: list[str]
    mouth: MouthLine
    scan_vertices: NDArray
    scan_faces: NDArray
    scan_side: NDArray
    scan_parent: NDArray
    kinematic: Any
    times: NDArray
    fps: float
    inverted_count: NDArray


@dataclass(frozen=True)
class FaceEvaluation:
    """The evaluate stage's output.

    ``fem``, ``kinematic``, ``tracked``: landmark measures of each variant (curves (T,) and
    (T, L) in the order of align's ``landmark_names``); ``mouth_corners`` the indices of
    ch_L and ch_R on that axis; ``times`` (T,) s; ``philtrum_right`` /
    ``philtrum_left`` (T,) m mean displacement of the free nodes of each philtrum region.
    With ground truth (else None): ``peak_frames`` expression -> frame; ``fidelity_fem`` /
    ``fidelity_kinematic`` relative displacement error per frame and region (``regions``);
    ``lip_gap_truth`` / ``lip_gap_fem`` / ``lip_gap_kinematic`` (T,) m; ``truth_frames``
    (F,) and ``error_fem`` / ``error_kinematic`` (F,) m RMS distance to the true surface;
    ``surfaces_fem`` / ``surfaces_kinematic`` the scan moved by each against the truth
    (silhouettes per frame and view of ``silhouette_views_deg``, triangle stretch);
    ``scan_error_fem`` / ``scan_error_kinematic`` (N,) float32 m, each scan vertex's largest
    distance over the frames from where the truth moves it (the viewer's error colours), NaN
    where it has no truth (``EvaluateParams.truth_max_distance_m``).
    """

    fem: LandmarkMeasures
    kinematic: LandmarkMeasures
    tracked: LandmarkMeasures
    mouth_corners: list[int]
    times: NDArray
    philtrum_right: NDArray
    philtrum_left: NDArray
    peak_frames: dict[str, int] | None = None
    regions: list[str] | None = None
    fidelity_fem: Fidelity | None = None
    fidelity_kinematic: Fidelity | None = None
    lip_gap_truth: NDArray | None = None
    lip_gap_fem: NDArray | None = None
    lip_gap_kinematic: NDArray | None = None
    truth_frames: NDArray | None = None
    error_fem: NDArray | None = None
    error_kinematic: NDArray | None = None
    silhouette_views_deg: list[float] | None = None
    surfaces_fem: SurfaceQuality | None = None
    surfaces_kinematic: SurfaceQuality | None = None
    scan_error_fem: NDArray | None = None
    scan_error_kinematic: NDArray | None = None


def evaluate_face(
    run: FaceRun, truth: Truth | None, params: EvaluateParams, cache: FileCache | None = None
) -> tuple[FaceEvaluation, dict[str, Any]]:
    """The measures of one run and its summary (rounded figures: mm, s, ratios); ``cache``
    keeps the scan's embedding in the tets (``physanim.mesh.embed``) and what the truth
    gives of the capture alone (:func:`capture_against_truth`)."""
    from physanim.evaluate.fidelity import REGIONS
    from physanim.evaluate.measures import driven_free_lag, landmark_measures, region_lags
    from physanim.mesh.embed import embedded_displacements
    from physanim.names import name_index

    names = run.landmark_names
    variants = {
        "fem": run.fem_landmarks,
        "kinematic": run.kinematic_landmarks,
        "tracked": run.tracked_landmarks,
    }
    measures = {label: landmark_measures(pts, names) for label, pts in variants.items()}
    ch = name_index(names, ["ch_L", "ch_R"])
    summary: dict[str, Any] = {
        label: {
            # over the frames whose landmarks were all tracked (NaN: none were)
            "mean_symmetry_cost": round(_finite_mean(m.cost[1:]), 4),
            "peak_mouth_corner_mm": [round(float(m.peak[i]) * 1e3, 3) for i in ch],
            "peak_mouth_corner_frame": [int(m.peak_frame[i]) for i in ch],
        }
        for label, m in measures.items()
    }
    disp = run.displacements
    free = np.setdiff1d(np.nonzero(run.skin)[0], run.driven)
    lag = driven_free_lag(disp, run.driven, free, params.max_lag_frames)
    summary["free_lag_s"] = round(lag / run.fps, 4)
    philtrum = philtrum_curves(run)
    summary["philtrum_peak_mm"] = {
        side: round(float(curve.max()) * 1e3, 4) for side, curve in philtrum.items()
    }
    # the FEM moves a sample of the scan's vertices as it moves the rendered scan: the same
    # points for every tet mesh, compared with the captured scan's same vertices
    scan_v = run.scan_vertices
    scan_idx, labels = scan_sample(
        scan_v, dict(zip(names, run.landmarks, strict=True)), params.error_max_points
    )
    fem_scan = scan_v + embedded_displacements(
        scan_v, run.scan_side, run.nodes, run.tets, run.mouth, disp, cache
    )
    fem_moved = fem_scan[:, scan_idx] - scan_v[scan_idx]
    captured = _rows(run.kinematic, scan_idx) - scan_v[scan_idx]
    lags = {}
    for names_of, labels_of in (
        (REGIONS, labels), (run.region_names, run.scan_labels[scan_idx])
    ):  # fmt: skip
        lags |= region_lags(
            fem_moved, captured, labels_of, names_of, params.max_lag_frames, params.min_motion_m
        )
    summary["lag_behind_capture_ms"] = {
        k: None if v is None else round(v / run.fps * 1e3, 2) for k, v in lags.items()
    }
    fields: dict[str, Any] = {}
    if truth is not None:
        sample = (scan_idx, labels, fem_moved, captured)
        found, figures = _against_truth(run, truth, params, fem_scan, sample, cache)
        fields.update(found)
        summary.update(figures)
    evaluation = FaceEvaluation(
        **measures,
        mouth_corners=[int(i) for i in ch],
        times=np.asarray(run.times),
        philtrum_right=philtrum["right"],
        philtrum_left=philtrum["left"],
        **fields,
    )
    return evaluation, summary


def scan_sample(
    scan_vertices: NDArray, landmarks: dict[str, NDArray], max_points: int
) -> tuple[NDArray, NDArray]:
    """The scan vertices the truth's figures use, the same for every tet mesh: their ids (S,)
    (at most ``max_points``, a fixed random draw) and their regions (S,)
    (``physanim.evaluate.fidelity.face_regions`` of the feature points ``landmarks``)."""
    from physanim.evaluate.fidelity import face_regions

    n = len(scan_vertices)
    ids = np.sort(np.random.default_rng(0).choice(n, min(n, max_points), False))
    return ids, face_regions(np.asarray(scan_vertices)[ids], landmarks)


def philtrum_curves(run: FaceRun) -> dict[str, NDArray]:
    """Mean displacement magnitude (T,) m of the free nodes of the right and left philtrum
    regions (cphs_R / cphs_L), keyed ``right`` / ``left``: each node weighted by its share of
    the region's volume (a quarter of each of its tets there), so that the mean is the
    region's, not the mesh's (a plain node mean weighs where nodes crowd: a mesh graded finer
    at the skin, which moves most, read 23 % more than a uniform one)."""
    from physanim.mesh.tetra import tet_volumes
    from physanim.names import name_index

    magnitude = np.linalg.norm(run.displacements, axis=-1)
    free = np.ones(len(run.nodes), dtype=bool)
    free[np.asarray(run.driven, dtype=np.int64)] = False
    out = {}
    for side, region in (("right", "cphs_R"), ("left", "cphs_L")):
        label = name_index(run.region_names, [region])[0]
        tets = run.tets[run.tet_labels == label]
        weight = (
            np.bincount(
                tets.ravel(),
                np.repeat(np.abs(tet_volumes(run.nodes, tets)) / 4.0, 4),
                minlength=len(run.nodes),
            )
            * free
        )
        total = weight.sum()
        out[side] = magnitude @ weight / total if total > 0 else np.zeros(len(run.displacements))
    return out


def _against_truth(
    run: FaceRun,
    truth: Truth,
    params: EvaluateParams,
    fem_scan: NDArray,
    sample: tuple[NDArray, NDArray, NDArray, NDArray],
    cache: FileCache | None = None,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Motion fidelity per frame and region, the lip gap, the surface distance and the
    surface quality of the FEM skin and the kinematic scan against the truth; ``fem_scan``
    (T, N, 3) m the scan moved by the FEM; ``sample`` the scan vertices the figures use
    (S,), their regions (S,) and their displacements (T, S, 3) m by the FEM and by the
    capture; ``cache`` keeps what does not depend on the FEM: (output fields, summary
    entries)."""
    from physanim.evaluate.fidelity import (
        REGIONS,
        lip_gap,
        lip_midline_points,
        motion_fidelity,
    )
    from physanim.evaluate.measures import surface_errors

    disp, mouth = run.displacements, run.mouth
    scan_idx, labels, fem_moved, captured = sample
    scan_v, scan_side = run.scan_vertices, run.scan_side
    lips = list(lip_midline_points(mouth, scan_v, scan_side, params.lip_offset_m))
    fem_lips = fem_scan[:, lips] - scan_v[lips]
    search = params.closest_points
    # the true motion of every scan vertex: its lip points', its sample's, its silhouettes'
    capture = capture_against_truth(run, truth, params, cache)
    scan_truth = capture.scan_truth
    true_gap = lip_gap(*(scan_v[lips][None] + scan_truth[:, lips]).transpose(1, 0, 2))
    kin = run.kinematic
    # only the sample's points on the true surface have a truth (not the scan's filled holes)
    has_truth = capture.truth_distance <= params.truth_max_distance_m
    keep = has_truth[scan_idx]
    scan_idx, labels = scan_idx[keep], labels[keep]
    fem_moved, captured = fem_moved[:, keep], captured[:, keep]
    # both on the same sample of scan vertices: the same points for every tet mesh (the skin
    # nodes, which the FEM's figure once used, crowd where a graded mesh is fine and weigh
    # that part of the face more: a 2 mm mesh refined at the lips read 0.175 at the jaw drop
    # against the uniform 2 mm mesh's 0.145)
    models = {  # their motion, the lip points moved, the true motion
        "fem": (
            fem_moved,
            scan_v[lips] + fem_lips,
            scan_truth[:, scan_idx],
        ),
        "kinematic": (
            captured,
            _rows(kin, np.asarray(lips)),
            scan_truth[:, scan_idx],
        ),
    }
    peaks = truth.peak_frames()
    fields: dict[str, Any] = {"peak_frames": peaks, "regions": list(REGIONS)}
    fields["lip_gap_truth"] = true_gap
    out: dict[str, Any] = {"peak_frames": peaks, "lip_gap_mm": {}, "fidelity": {}}
    out["points_without_truth"] = {"scan": int((~has_truth).sum()), "sample": int((~keep).sum())}
    for label, (moved, lip_pts, true) in models.items():
        fid = motion_fidelity(moved, true, labels, params.min_motion_m)
        fields[f"fidelity_{label}"] = fid
        gap = lip_gap(lip_pts[:, 0], lip_pts[:, 1])
        fields[f"lip_gap_{label}"] = gap
        out["fidelity"][label] = {
            name: {
                "overall": _r(fid.overall[f]),
                **{r: _r(fid.regions[f, i]) for i, r in enumerate(REGIONS)},
            }
            for name, f in peaks.items()
        } | {"worst_frame": int(np.nanargmax(fid.overall)), "worst": _r(np.nanmax(fid.overall))}
        out["lip_gap_mm"][label] = {
            name: round(float(gap[f]) * 1e3, 3) for name, f in peaks.items()
        }
    out["lip_gap_mm"]["truth"] = {n: round(float(true_gap[f]) * 1e3, 3) for n, f in peaks.items()}
    # an edit's price where it acts (a smile's gesture at the smile)
    out["inverted_tets_at_peaks"] = {n: int(run.inverted_count[f]) for n, f in peaks.items()}

    # the RMS point-to-surface distance (blind to sliding and to a shut mouth)
    frames = list(range(0, disp.shape[0], params.error_every_frames))
    err_fem, err_kin = surface_errors(  # the FEM skin and the capture on the same scan sample
        [fem_scan[:, scan_idx], scan_v[scan_idx] + captured],
        truth.vertices,
        truth.faces,
        frames,
        search,
    )
    fields.update(truth_frames=np.asarray(frames), error_fem=err_fem, error_kinematic=err_kin)
    out["surface_distance_rms_mm"] = {
        "fem": round(float(np.sqrt(np.mean(err_fem**2))) * 1e3, 3),
        "kinematic": round(float(np.sqrt(np.mean(err_kin**2))) * 1e3, 3),
    }
    surfaces, figures = _surfaces(run, truth, params, fem_scan, capture)
    fields.update(surfaces)
    fields["scan_error_fem"] = _worst_distance(fem_scan - scan_v, scan_truth, has_truth)
    fields["scan_error_kinematic"] = _worst_distance(
        np.asarray(kin, dtype=np.float64) - scan_v, scan_truth, has_truth
    )
    out["surfaces"] = figures
    return fields, out


#: what the capture-side cache holds changes with this (bump when it is computed differently)
CAPTURE_CACHE_VERSION = 2


@dataclass(frozen=True)
class CaptureAgainstTruth:
    """What the truth gives of a run's capture alone, the same for every FEM of it:
    ``scan_truth`` (T, N, 3) m the true motion of each scan vertex (the true surface point
    closest to it at the first frame, followed), ``truth_distance`` (N,) m its distance to
    that point, ``truth_masks`` (T, V, H, W) bool the silhouettes of the scan moved so, and
    the captured scan's surface quality ``kinematic``."""

    scan_truth: NDArray
    truth_distance: NDArray
    truth_masks: NDArray
    kinematic: SurfaceQuality


def _cameras(run: FaceRun, params: EvaluateParams) -> list:
    from physanim.evaluate.surfaces import view_cameras

    return view_cameras(run.scan_vertices, params.silhouette_size_px, params.silhouette_views_deg)


def _away_from_seam(run: FaceRun) -> NDArray:
    from physanim.evaluate.surfaces import seam_faces

    return ~seam_faces(run.scan_faces, run.scan_parent)


def capture_against_truth(
    run: FaceRun, truth: Truth, params: EvaluateParams, cache: FileCache | None = None
) -> CaptureAgainstTruth:
    """:class:`CaptureAgainstTruth` of ``run``, kept in ``cache`` by the content of what it is
    made from (the truth, the scan, the captured motion, the settings): a material edit, which
    changes only the FEM, reads it back instead of making it again (the demo's evaluate: 4.9
    -> 3.8 s)."""
    from physanim.evaluate.fidelity import follow_truth
    from physanim.evaluate.surfaces import silhouettes, surface_quality
    from physanim.store.file_cache import content_digest

    scan_v, faces = run.scan_vertices, run.scan_faces
    kinematic = np.asarray(run.kinematic, dtype=np.float64)
    size, search = params.silhouette_size_px, params.closest_points
    digest = content_digest(
        "capture-against-truth", CAPTURE_CACHE_VERSION, np.asarray(truth.vertices),
        truth.faces, scan_v, faces, run.scan_parent, kinematic, size,
        params.silhouette_views_deg, search,
    )  # fmt: skip
    found = None if cache is None else cache.fetch(digest, ".npz")
    if found is not None:
        with np.load(found) as z:
            quality = SurfaceQuality(z["iou"], z["stretch"], z["inverted"])
            return CaptureAgainstTruth(z["scan_truth"], z["distance"], z["masks"], quality)
    true = follow_truth(scan_v, truth.vertices, truth.faces, search)
    cameras = _cameras(run, params)
    masks = silhouettes(scan_v + true.displacement, faces, cameras, size)
    quality = surface_quality(kinematic, masks, faces, _away_from_seam(run), cameras, size)
    out = CaptureAgainstTruth(true.displacement, true.distance, masks, quality)
    if cache is not None:
        arrays = dict(
            scan_truth=true.displacement, distance=true.distance, masks=masks,
            iou=quality.silhouette_iou, stretch=quality.max_stretch, inverted=quality.inverted,
        )  # fmt: skip
        cache.put(digest, ".npz", lambda path: np.savez(path, **arrays))
    return out


def _surfaces(
    run: FaceRun,
    truth: Truth,
    params: EvaluateParams,
    fem_scan: NDArray,
    capture: CaptureAgainstTruth,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The scan moved by the FEM (``fem_scan`` (T, N, 3) m) and by the capture against the
    same scan moved by the truth (``capture``: its silhouettes and the captured scan's
    quality): silhouettes per frame and view, triangle stretch outside the lip seam; the
    truth's own largest stretch at the peaks: (output fields, summary entries)."""
    from physanim.evaluate.surfaces import RestTriangles, surface_quality

    faces = run.scan_faces
    views = params.silhouette_views_deg
    found = {
        "fem": surface_quality(
            fem_scan, capture.truth_masks, faces, _away_from_seam(run), _cameras(run, params),
            params.silhouette_size_px,
        ),
        "kinematic": capture.kinematic,
    }  # fmt: skip
    own = RestTriangles.of(truth.vertices[0], truth.faces)  # at the peaks: 1 s per 30 frames
    stretch_truth = max(
        own.stretch(truth.vertices[f])[0].max() for f in truth.peak_frames().values()
    )
    figures: dict[str, Any] = {
        label: {
            "silhouette_iou_min": {
                f"{v:g}": _r(q.silhouette_iou[:, i].min()) for i, v in enumerate(views)
            },  # fmt: skip
            "silhouette_worst_frame": int(np.argmin(q.silhouette_iou.min(axis=1))),
            "max_stretch": _r(q.max_stretch.max()),
            "max_stretch_frame": int(np.argmax(q.max_stretch)),
            "inverted_max": int(q.inverted.max()),
        }
        for label, q in found.items()
    }
    figures["truth"] = {"max_stretch_at_peaks": _r(stretch_truth)}
    fields = {
        "silhouette_views_deg": list(views),
        "surfaces_fem": found["fem"],
        "surfaces_kinematic": found["kinematic"],
    }
    return fields, figures


def _worst_distance(moved: NDArray, true: NDArray, has_truth: NDArray) -> NDArray:
    """(N,) float32 m: the largest distance over the T frames between the displacements
    ``moved`` and ``true`` (T, N, 3) m of each point; NaN where it has no truth
    (``has_truth`` (N,) False)."""
    worst = np.linalg.norm(moved - true, axis=2).max(axis=0).astype(np.float32)
    return np.where(has_truth, worst, np.float32(np.nan))


def _rows(frames: Any, idx: NDArray) -> NDArray:
    """``frames[:, idx]`` (T, len(idx), 3) of a numpy or Zarr array (T, N, 3)."""
    if isinstance(frames, np.ndarray):
        return frames[:, idx]
    return np.asarray(frames.get_orthogonal_selection((slice(None), idx, slice(None))))


def _finite_mean(x: NDArray) -> float:
    """The mean of the finite entries of ``x``, NaN when there are none."""
    finite = x[np.isfinite(x)]
    return float(finite.mean()) if finite.size else math.nan


def _r(x: float) -> float | None:
    return None if not math.isfinite(float(x)) else round(float(x), 4)
