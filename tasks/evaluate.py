"""Stage ``evaluate``: symmetry cost, mouth-corner and landmark curves, lag, truth errors.

The same measures for the simulated skin (landmark nodes), the tracked landmarks and the
kinematic model; on the demo, errors of the kinematic and FEM skin against the true surface.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field

from physanim.pipeline import StageContext, StageSpec


class EvaluateParams(BaseModel):
    """Evaluation settings."""

    model_config = ConfigDict(extra="forbid")
    truth: str = Field("ground_truth.zarr", description="ground truth in the dataset, if any")
    error_every_frames: int = Field(5, ge=1, le=1000, description="frame stride of truth errors")
    error_max_points: int = Field(4000, ge=100, le=10**6, description="skin points sampled")
    max_lag_frames: int = Field(15, ge=1, le=300, description="search range of the lag, frames")


def compute(ctx: StageContext) -> None:
    """Measures per variant (fem, kinematic, tracked) under ``<variant>/``; truth errors."""
    import numpy as np
    import zarr

    from physanim.evaluate.measures import driven_free_lag, landmark_measures, surface_error

    params: EvaluateParams = ctx.params  # type: ignore[assignment]
    aligned, mesh, sim = ctx.input("align"), ctx.input("tetra"), ctx.input("simulate")
    tracked = ctx.input("track")
    names = list(aligned.attrs["landmark_names"])
    nodes = mesh["nodes"][...]
    lm_nodes = mesh["landmark_node"][...]
    disp = sim["displacements"][...].astype(np.float64)
    fem = nodes[lm_nodes] + disp[:, lm_nodes]
    kin_motion = aligned["motion"][...].astype(np.float64)[:, aligned["landmark_vertices"][...]]
    track_names = list(tracked.attrs["names"])
    # tracked points are in the camera frame: remove the head pose (camera <- actor) per frame
    cam = tracked["points"][...][:, [track_names.index(n) for n in names]]
    pose = tracked["head_pose"][...]
    tracked_pts = np.einsum("tji,tkj->tki", pose[:, :3, :3], cam - pose[:, None, :3, 3])
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
    driven = sim["driven_nodes"][...]
    free = np.setdiff1d(np.nonzero(skin)[0], driven)
    fps = float(aligned.attrs["fps"])
    lag = driven_free_lag(disp, driven, free, params.max_lag_frames)
    summary["free_lag_s"] = round(lag / fps, 4)
    ctx.out.attrs["landmark_names"] = names

    truth = ctx.dataset_dir / params.truth
    if truth.exists():
        gt = zarr.open_group(truth, mode="r")
        tv, tf = gt["vertices_actor"], gt["faces"][...]
        frames = list(range(0, disp.shape[0], params.error_every_frames))
        true_v = np.zeros((disp.shape[0], *tv.shape[1:]))
        true_v[frames] = tv.get_orthogonal_selection((frames, slice(None), slice(None)))
        rng = np.random.default_rng(0)
        skin_idx = np.nonzero(skin)[0]
        skin_idx = rng.choice(skin_idx, min(len(skin_idx), params.error_max_points), False)
        n_scan = aligned["scan_vertices"].shape[0]
        scan_idx = rng.choice(n_scan, min(n_scan, params.error_max_points), False)
        fem_skin = nodes[skin_idx][None] + disp[:, skin_idx]
        kin_skin = (
            aligned["kinematic"]
            .get_orthogonal_selection((slice(None), np.sort(scan_idx), slice(None)))
            .astype(np.float64)
        )
        err_fem = surface_error(fem_skin, true_v, tf, frames)
        err_kin = surface_error(kin_skin, true_v, tf, frames)
        ctx.write("truth_frames", np.asarray(frames))
        ctx.write("error_fem", err_fem)
        ctx.write("error_kinematic", err_kin)
        summary["truth_rms_mm"] = {
            "fem": round(float(np.sqrt(np.mean(err_fem**2))) * 1e3, 3),
            "kinematic": round(float(np.sqrt(np.mean(err_kin**2))) * 1e3, 3),
        }
    ctx.summary.update(summary)


SPEC = StageSpec(
    name="evaluate",
    upstream=("track", "align", "tetra", "simulate"),
    params=EvaluateParams,
    version="2",
    compute=compute,
    doc="symmetry cost, mouth-corner curves, driven/free lag, errors against truth",
)
