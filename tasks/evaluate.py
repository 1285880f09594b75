"""Stage ``evaluate``: symmetry cost, mouth-corner curves, lag, and how well the simulated face
performs the capture.

The seed's measures for the simulated skin (landmark nodes), the tracked landmarks and the
kinematic model; the peak displacement of the philtrum regions (where the regional models
differ); and, on a dataset with ground truth, the motion fidelity of the FEM skin and of the
kinematic scan (relative displacement error per frame and facial region,
``physanim.evaluate.fidelity``), the lip gap against the truth, and the RMS point-to-surface
distance to the true surface.
"""

from __future__ import annotations

from collections.abc import Mapping

from pydantic import BaseModel, ConfigDict, Field

from physanim.pipeline import DatasetParams, StageContext, StageSpec


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
    lip_offset_m: float = Field(
        0.003, gt=0.0, le=0.02, description="lip midline points this far above / below the mouth, m"
    )


def fingerprint(dataset: DatasetParams, params: BaseModel) -> Mapping[str, object]:
    """Size and modification time of every file of the ground truth (an edited truth re-runs
    evaluate)."""
    from physanim.store import files_fingerprint

    truth = dataset.path / params.truth  # type: ignore[attr-defined]
    if not truth.exists():
        return {"truth": "none"}
    files = [p for p in truth.rglob("*") if p.is_file()] if truth.is_dir() else [truth]
    return {"truth": files_fingerprint(files, dataset.path)}


def compute(ctx: StageContext) -> None:
    """Measures per variant (fem, kinematic, tracked) under ``<variant>/``; philtrum peaks;
    with truth: fidelity, lip gap and surface distance per frame."""
    import numpy as np

    from physanim.evaluate.measures import driven_free_lag, landmark_measures, surface_errors
    from physanim.face.drive import head_frame

    params: EvaluateParams = ctx.params  # type: ignore[assignment]
    aligned, mesh, sim = ctx.input("align"), ctx.input("tetra"), ctx.input("simulate")
    tracked, mats = ctx.input("track"), ctx.input("materials")
    names = list(aligned.attrs["landmark_names"])
    nodes = mesh["nodes"][...]
    disp = sim["displacements"][...].astype(np.float64)
    fem = nodes[mesh["landmark_node"][...]] + disp[:, mesh["landmark_node"][...]]
    kin_motion = aligned["motion"][...].astype(np.float64)[:, aligned["landmark_vertices"][...]]
    track_names = list(tracked.attrs["names"])
    stabilised = head_frame(tracked["points"][...], tracked["head_pose"][...])
    tracked_pts = stabilised[:, [track_names.index(n) for n in names]]
    variants = {"fem": fem, "kinematic": kin_motion, "tracked": tracked_pts}
    summary: dict[str, object] = {}
    for label, pts in variants.items():
        m = landmark_measures(pts, names)
        ctx.write_record(m, prefix=label)
        ch = [names.index("ch_L"), names.index("ch_R")]
        summary[label] = {
            "mean_symmetry_cost": round(float(np.mean(m.cost[1:])), 4),
            "peak_mouth_corner_mm": [round(float(m.peak[i]) * 1e3, 3) for i in ch],
            "peak_mouth_corner_frame": [int(m.peak_frame[i]) for i in ch],
        }
    skin = mesh["skin"][...]
    driven = np.union1d(sim["driven_nodes"][...], sim["spring_nodes"][...])
    free = np.setdiff1d(np.nonzero(skin)[0], driven)
    fps = float(aligned.attrs["fps"])
    lag = driven_free_lag(disp, driven, free, params.max_lag_frames)
    summary["free_lag_s"] = round(lag / fps, 4)
    summary["philtrum_peak_mm"] = _philtrum_peaks(ctx, mesh, mats, disp, driven)
    ctx.out.attrs["landmark_names"] = names

    truth_path = ctx.dataset_dir / params.truth
    if truth_path.exists():
        summary.update(_against_truth(ctx, params, aligned, mesh, disp))
        # the RMS point-to-surface distance (blind to sliding and to a shut mouth)
        from physanim.evaluate.truth import load_truth

        truth = load_truth(truth_path, disp.shape[0])
        frames = list(range(0, disp.shape[0], params.error_every_frames))
        rng = np.random.default_rng(0)
        skin_idx = np.nonzero(skin)[0]
        skin_idx = rng.choice(skin_idx, min(len(skin_idx), params.error_max_points), False)
        n_scan = aligned["scan_vertices"].shape[0]
        scan_idx = np.sort(rng.choice(n_scan, min(n_scan, params.error_max_points), False))
        fem_skin = nodes[skin_idx][None] + disp[:, skin_idx]
        kin_skin = aligned["kinematic"].get_orthogonal_selection(
            (slice(None), scan_idx, slice(None))
        )
        err_fem, err_kin = surface_errors(
            [fem_skin, np.asarray(kin_skin)], truth.vertices, truth.faces, frames
        )
        ctx.write("truth_frames", np.asarray(frames))
        ctx.write("error_fem", err_fem)
        ctx.write("error_kinematic", err_kin)
        summary["surface_distance_rms_mm"] = {
            "fem": round(float(np.sqrt(np.mean(err_fem**2))) * 1e3, 3),
            "kinematic": round(float(np.sqrt(np.mean(err_kin**2))) * 1e3, 3),
        }
    ctx.summary.update(summary)


def _philtrum_peaks(ctx, mesh, mats, disp, driven) -> dict[str, float]:
    """Peak (over frames) of the mean displacement (mm) of the free nodes of the right and
    left philtrum regions (cphs_R / cphs_L); curves in ``philtrum/{right,left}`` (T,) m."""
    import numpy as np

    tets, labels = mesh["tets"][...], mats["tet_labels"][...]
    regions = list(mats.attrs["region_names"])
    magnitude = np.linalg.norm(disp, axis=-1)
    out = {}
    for side, region in (("right", "cphs_R"), ("left", "cphs_L")):
        nodes = np.setdiff1d(np.unique(tets[labels == regions.index(region)]), driven)
        curve = magnitude[:, nodes].mean(axis=1) if len(nodes) else np.zeros(len(disp))
        ctx.write(f"philtrum_{side}", curve)
        out[side] = round(float(curve.max()) * 1e3, 4)
    return out


def _against_truth(ctx, params, aligned, mesh, disp) -> dict[str, object]:
    """Motion fidelity per frame and region, and the lip gap, of the FEM skin and the
    kinematic scan against the truth; returns the summary entries."""
    import numpy as np

    from physanim.evaluate.fidelity import (
        REGIONS,
        face_regions,
        follow_truth,
        lip_gap,
        lip_midline_points,
        motion_fidelity,
    )
    from physanim.evaluate.truth import load_truth
    from physanim.mesh.embed import embedding_matrix
    from physanim.mesh.kinematic import blend_frames
    from physanim.mesh.seam import MouthLine

    truth = load_truth(ctx.dataset_dir / params.truth, disp.shape[0])
    names = list(aligned.attrs["landmark_names"])
    landmarks = dict(zip(names, aligned["landmarks"][...], strict=True))
    mouth = MouthLine(aligned["mouth_line"][...], float(aligned.attrs["lip_band_m"]))
    nodes, skin = mesh["nodes"][...], np.nonzero(mesh["skin"][...])[0]
    scan_v, scan_side = aligned["scan_vertices"][...], aligned["scan_side"][...]
    rng = np.random.default_rng(0)
    scan_idx = np.sort(rng.choice(len(scan_v), min(len(scan_v), params.error_max_points), False))
    lips = list(lip_midline_points(mouth, scan_v, scan_side, params.lip_offset_m))
    tets = mesh["tets"][...]
    embed = embedding_matrix(  # the FEM moves the lip points as it moves the rendered scan
        scan_v[lips], scan_side[lips], nodes, tets, mouth.side(nodes[tets].mean(axis=1))
    )
    true_lips = follow_truth(scan_v[lips], truth.vertices, truth.faces).displacement
    true_gap = lip_gap(*(scan_v[lips][None] + true_lips).transpose(1, 0, 2))
    kin = aligned["kinematic"]
    models = {
        "fem": (nodes[skin], disp[:, skin], scan_v[lips] + blend_frames(embed, disp)),
        "kinematic": (
            scan_v[scan_idx],
            kin.get_orthogonal_selection((slice(None), scan_idx, slice(None))) - scan_v[scan_idx],
            kin.get_orthogonal_selection((slice(None), lips, slice(None))),
        ),
    }
    peaks = truth.peak_frames()
    ctx.write("lip_gap_truth", true_gap)
    out: dict[str, object] = {"peak_frames": peaks, "lip_gap_mm": {}, "fidelity": {}}
    for label, (rest, moved, lip_pts) in models.items():
        tm = follow_truth(rest, truth.vertices, truth.faces)
        fid = motion_fidelity(moved, tm.displacement, face_regions(rest, landmarks),
                              params.min_motion_m)  # fmt: skip
        ctx.write_record(fid, prefix=f"fidelity_{label}")
        gap = lip_gap(lip_pts[:, 0], lip_pts[:, 1])
        ctx.write(f"lip_gap_{label}", gap)
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
    ctx.out.attrs["regions"] = list(REGIONS)
    return out


def _r(x: float) -> float | None:
    import math

    return None if not math.isfinite(float(x)) else round(float(x), 4)


SPEC = StageSpec(
    name="evaluate",
    upstream=("track", "align", "tetra", "materials", "simulate"),
    params=EvaluateParams,
    version="4",
    compute=compute,
    doc="symmetry cost, mouth corners, lag, philtrum peaks; with truth: motion fidelity per "
    "region, lip gap, surface distance",
    fingerprint=fingerprint,
)
