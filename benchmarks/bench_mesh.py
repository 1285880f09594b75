"""Benchmark of the mesh stages on the demo face (face000): prints numbers, no assertions.

Compares side by side, in the same process: the indexed closest-point binding against a
brute-force minimum over all triangles; and the kinematic model's markers against ground-truth
marker trajectories of the demo performance (the wireframe is moved by the same ground-truth
field, i.e. perfect tracking, so the RMS is the kinematic model's own interpolation error).

Usage: .venv/bin/python benchmarks/bench_mesh.py [--frames 60] [--out DIR]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from results import Table, describe, record  # benchmarks/results.py, beside this script

from physanim.capture.actor import build_actor
from physanim.capture.markers import place_markers
from physanim.capture.performance import AnalyticFaceField, demo_performance
from physanim.face.landmarks import FEATURE_POINTS
from physanim.face.model import load_face_model
from physanim.fem.region_materials import tet_materials
from physanim.mesh.align import align_motion_mesh
from physanim.mesh.binding import bind_points, closest_points_on_triangles
from physanim.mesh.kinematic import animate_bound_points
from physanim.mesh.params import (
    AlignParams,
    MaterialModel,
    MaterialsParams,
    ScanParams,
    TetraParams,
)
from physanim.mesh.regions import LABEL_NAMES, plot_regions, region_areas, skin_regions, tet_regions
from physanim.mesh.remesh import prepare_scan
from physanim.mesh.tetra import label_nodes, landmark_nodes, tetrahedralize_surface
from physanim.mesh.tissue import build_tissue_surface


class Timer:
    """Prints and keeps (``Timer.done``) the wall seconds of a block."""

    done: list[list] = []

    def __init__(self, name: str) -> None:
        self.name = name

    def __enter__(self) -> Timer:
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.s = time.perf_counter() - self.t0
        print(f"  {self.name:<42s} {self.s:8.2f} s")
        Timer.done.append([self.name, self.s])


def brute_force_distance(points: np.ndarray, v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Minimum distance (N,) over every triangle, in chunks of points."""
    out = np.empty(len(points))
    t = v[f]
    for s in range(0, len(points), 512):
        p = points[s : s + 512, None, :]
        _, d2, _ = closest_points_on_triangles(p, t[None, :, 0], t[None, :, 1], t[None, :, 2])
        out[s : s + 512] = np.sqrt(d2.min(axis=1))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--out", type=Path, default=None, help="folder for the regions PNG")
    args = ap.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench_mesh_"))
    out.mkdir(parents=True, exist_ok=True)
    sp_, ap_, tp, mp = ScanParams(), AlignParams(), TetraParams(), MaterialsParams()

    print("scan preparation")
    actor = build_actor()
    with Timer("prepare_scan (close holes + remesh)"):
        v, f = prepare_scan(actor.vertices, actor.faces, sp_.remesh_edge_length_m)
    print(f"  skin: {len(v)} vertices, {len(f)} triangles (target 20-30k vertices)")
    markers = place_markers(v, f)
    pos = markers.positions(v, f)
    lms = {n: pos[markers.names.index(n)] for n in FEATURE_POINTS}

    print("alignment")
    model = load_face_model()
    lm_idx = model.index(FEATURE_POINTS)
    targets = np.array([lms[n] for n in FEATURE_POINTS])
    nose = FEATURE_POINTS.index("pronasale")
    neutral = model.deform(su=np.random.default_rng(0).uniform(-1, 1, len(model.su_names)))
    with Timer("align_motion_mesh (per_axis + refinement)"):
        al = align_motion_mesh(neutral, model.triangles, lm_idx, v, f, targets, nose, ap_)
    d = bind_points(al.vertices, v, f).distance
    print(
        f"  wireframe-to-skin distance: median {np.median(d) * 1e3:.3f} mm, "
        f"landmark residual max {np.abs(al.vertices[lm_idx] - targets).max() * 1e3:.3f} mm"
    )

    print("binding (indexed vs brute force, same process)")
    with Timer("bind_points (cKDTree candidates)"):
        b = bind_points(v, al.vertices, model.triangles, ap_.binding_candidates)
    with Timer("brute force over all triangles"):
        ref = brute_force_distance(v, al.vertices, model.triangles)
    print(
        f"  max |indexed - brute force| = {np.abs(b.distance - ref).max():.3e} m; "
        f"regions face/edge/vertex = {np.bincount(b.region, minlength=3).tolist()}"
    )

    print(f"kinematic model ({args.frames} frames, perfect tracking of the wireframe)")
    perf = demo_performance(args.frames, 30.0, seed=0)
    field = AnalyticFaceField(ch_left=tuple(lms["ch_L"]), ch_right=tuple(lms["ch_R"]))
    pose = perf.head_pose()

    def world(x0: np.ndarray) -> np.ndarray:
        disp = np.stack([field.displacement(x0, p) for p in perf.params])
        x = x0[None] + disp
        return np.einsum("tij,tnj->tni", pose[:, :3, :3], x) + pose[:, None, :3, 3]

    motion = world(al.vertices)
    truth = world(pos)
    with Timer("animate_bound_points"):
        anim = animate_bound_points(v, b, model.triangles, motion)
    est = markers.positions(anim, f)
    err = np.linalg.norm(est - truth, axis=2)
    moved = np.linalg.norm(truth - truth[:1], axis=2)
    print(
        f"  marker RMS error {np.sqrt(np.mean(err**2)) * 1e3:.3f} mm, max {err.max() * 1e3:.3f}"
        f" mm (marker motion up to {moved.max() * 1e3:.2f} mm)"
    )

    print("tissue volume + tetrahedralisation (default TetraParams)")
    with Timer("build_tissue_surface"):
        surf = build_tissue_surface(v, f, lms, tp)
    with Timer("tetrahedralize_surface (fTetWild)"):
        mesh, q = tetrahedralize_surface(surf.vertices, surf.faces, tp)
    with Timer("label_nodes"):
        labels = label_nodes(mesh, surf, tp)
        no_seam = np.zeros(len(mesh.nodes), dtype=np.int8)
        _, lm_distance = landmark_nodes(
            mesh.nodes, labels.skin, no_seam, targets, np.zeros(len(targets))
        )
    for k, val in q.as_dict().items():
        print(f"  {k:<24s} {val:.4g}" if isinstance(val, float) else f"  {k:<24s} {val}")
    print(
        f"  enclosed volume {surf.enclosed_volume():.4g} m^3; skin nodes {labels.skin.sum()}, "
        f"bone nodes {labels.bone.sum()}, landmark-node distance max "
        f"{lm_distance.max() * 1e3:.2f} mm"
    )

    print("regions + materials")
    skin_lab = skin_regions(v, lms, mp)
    tet_lab = tet_regions(mesh.nodes, mesh.tets, v, skin_lab)
    areas = region_areas(v, f, skin_lab)
    print(
        "  skin area per region (cm^2): "
        + ", ".join(f"{n} {a * 1e4:.2f}" for n, a in zip(LABEL_NAMES, areas, strict=True))
    )
    print(
        "  tets per region: "
        + ", ".join(
            f"{n} {c}" for n, c in zip(LABEL_NAMES, np.bincount(tet_lab, minlength=7), strict=True)
        )
    )
    uniform = MaterialModel(
        name="uniform", default={"E_kPa": 192.4, "nu": 0.495, "eta_Pa_s": 476.8, "rho_kg_m3": 1100}
    )
    mat = tet_materials(tet_lab, uniform)
    print(
        f"  uniform model: E {mat.E_Pa.min():.4g}-{mat.E_Pa.max():.4g} Pa over {len(mat.E_Pa)} tets"
    )
    png = plot_regions(v, f, skin_lab, out / "regions.png", lms)
    print(f"  regions render: {png}")
    quality = [[k, v] for k, v in q.as_dict().items()]
    times = dict(Timer.done)
    record(
        "bench_mesh",
        [
            Table("mesh stages at full size", ["step", "wall_s"], Timer.done),
            Table("tet mesh quality (fTetWild)", ["figure", "value"], quality),
        ],  # fmt: skip
        **describe(__doc__, "bench_mesh"),
        notes=f"skin {len(v)} vertices; tets: {len(mesh.nodes)} nodes, {len(mesh.tets)} tets",
        headline={
            "binding_s": times["bind_points (cKDTree candidates)"],
            "ftetwild_s": times["tetrahedralize_surface (fTetWild)"],
        },  # fmt: skip
    )


if __name__ == "__main__":
    main()
