"""Benchmark the FEM core on a face-scale tet mesh (~20k DOF): assembly, factorisation,
time per Newmark step and real-time factor, default vs a plain-SuperLU baseline.

Run: .venv/bin/python benchmarks/bench_fem.py [--edge 0.0053] [--steps 1000]
The mesh is a curved 15 x 20 x 1.5 cm shell (face-like slab) tetrahedralised with fTetWild;
back side fixed, 12 front nodes driven at 30 fps, dt = 1e-3 s, seed's uniform material.
"""

from __future__ import annotations

import argparse
import resource
import time

import numba
import numpy as np
import pytetwild
import pyvista as pv

from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.newmark import Newmark, State
from physanim.fem.params import SimulateParams
from physanim.fem.simulate import simulate

CURV = 4.0  # 1/m, bend z += CURV x^2 (face-like curvature)


def face_slab(edge: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Curved shell tets; returns nodes (N, 3) m, tets (M, 4), unbent thickness coord (N,)."""
    box = pv.Box(bounds=(-0.075, 0.075, -0.1, 0.1, 0.0, 0.015), level=12).triangulate()
    pts = np.asarray(box.points, dtype=np.float64)
    pts[:, 2] += CURV * pts[:, 0] ** 2
    faces = box.faces.reshape(-1, 4)[:, 1:].astype(np.int32)
    nodes, tets = pytetwild.tetrahedralize(pts, faces, edge_length_abs=edge)
    tets = tets.astype(np.int64)
    x = nodes[tets]
    neg = np.linalg.det(x[:, 1:] - x[:, :1]) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return nodes, tets, nodes[:, 2] - CURV * nodes[:, 0] ** 2


def boundary(nodes, depth, n_driven=12):
    fixed = np.flatnonzero(depth < 1e-3)
    front = np.flatnonzero(depth > 0.015 - 1e-3)
    rng = np.random.default_rng(0)
    targets = np.c_[rng.uniform(-0.05, 0.05, n_driven), rng.uniform(-0.07, 0.07, n_driven)]
    dist = np.linalg.norm(nodes[front, None, :2] - targets[None], axis=2)
    driven = np.unique(front[dist.argmin(axis=0)])
    return fixed, driven


def trajectories(n_frames, n_driven, frame_dt):
    t = frame_dt * np.arange(n_frames)
    rng = np.random.default_rng(1)
    amp = rng.uniform(1e-3, 4e-3, (1, n_driven, 3))
    phase = rng.uniform(0, np.pi, (1, n_driven, 3))
    return (
        amp
        * np.sin(2 * np.pi * 1.5 * t[:, None, None] + phase)
        * np.sin(np.pi * t)[:, None, None] ** 2
    )


def time_steps(model, pres, dt, solver, n_steps):
    """Factorisation and per-step time of the linear Newmark with one solver."""
    t0 = time.perf_counter()
    nm = Newmark(model.K, model.M, model.C, dt, pres, solver, model.split)
    t_fac = time.perf_counter() - t0
    state = State.rest(model.n_dofs)
    rng = np.random.default_rng(2)
    d_c = rng.normal(size=len(pres)) * 1e-4
    z = np.zeros(len(pres))
    t0 = time.perf_counter()
    for i in range(n_steps):
        nm.step(state, d_c * np.sin(i * dt * 10), z, z)
    return t_fac, (time.perf_counter() - t0) / n_steps, nm


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--edge", type=float, default=0.0053, help="fTetWild edge length, m")
    ap.add_argument("--steps", type=int, default=1000, help="Newmark steps for the default run")
    ap.add_argument("--baseline-steps", type=int, default=100, help="steps per baseline run")
    args = ap.parse_args()
    dt, frame_dt = 1e-3, 1.0 / 30.0

    t0 = time.perf_counter()
    nodes, tets, depth = face_slab(args.edge)
    fixed, driven = boundary(nodes, depth)
    print(
        f"mesh: {len(nodes)} nodes, {len(tets)} tets, {3 * len(nodes)} DOF "
        f"({len(fixed)} fixed, {len(driven)} driven nodes); "
        f"meshing {time.perf_counter() - t0:.1f} s"
    )
    mat = TetMaterials.uniform(len(tets))
    pres = (3 * np.concatenate([driven, fixed])[:, None] + np.arange(3)).ravel()

    all_threads = numba.get_num_threads()
    print(f"\n{'config':34s} {'assembly s':>10s} {'factor s':>9s} {'ms/step':>8s} {'RTF':>6s}")
    for form in ("anp", "p1"):
        t0 = time.perf_counter()
        model = build_model(nodes, tets, mat, SimulateParams(formulation=form))
        t_asm = time.perf_counter() - t0
        for solver, threads in (("cholmod", all_threads), ("cholmod", 1), ("superlu", 1),
                                ("superlu_colamd", 1)):  # fmt: skip
            numba.set_num_threads(threads)  # our solve and products; SuperLU is serial anyway
            t_fac, per_step, _ = time_steps(model, pres, dt, solver, args.baseline_steps)
            numba.set_num_threads(all_threads)
            name = f"{form} / {solver}" + (f", {threads} thread(s)" if solver == "cholmod" else "")
            print(
                f"{name:34s} {t_asm:10.2f} {t_fac:9.2f} {1e3 * per_step:8.2f} {dt / per_step:6.2f}"
            )

    params = SimulateParams(dt=dt)
    n_frames = int(np.ceil(args.steps / np.ceil(frame_dt / dt))) + 1
    traj = trajectories(n_frames, len(driven), frame_dt)
    res = simulate(nodes, tets, mat, driven, traj, frame_dt, fixed, params)
    n_steps = (n_frames - 1) * res.n_substeps
    tm = res.timings
    print(
        f"\ndefault simulate() (anp, consistent mass, auto solver): {n_steps} steps of "
        f"{res.dt * 1e3:.3f} ms in {tm['stepping']:.2f} s stepping "
        f"({1e3 * tm['stepping'] / n_steps:.2f} ms/step incl. per-frame energies, stress, "
        f"inversion check; RTF {res.dt * n_steps / tm['stepping']:.2f}); assembly "
        f"{tm['assembly']:.2f} s, factorisation {tm['factorization']:.2f} s"
    )
    print(
        f"  max |d| {np.abs(res.displacements).max() * 1e3:.2f} mm, max von Mises "
        f"{res.max_von_mises.max():.0f} Pa, inverted tets {res.inverted_tets.size}"
    )

    n_cor = 3
    res_c = simulate(
        nodes,
        tets,
        mat,
        driven,
        traj[: n_cor + 1],
        frame_dt,
        fixed,
        SimulateParams(dt=dt, corotational=True),
    )
    steps_c = n_cor * res_c.n_substeps
    print(
        f"corotational: {1e3 * res_c.timings['stepping'] / steps_c:.1f} ms/step over {steps_c} "
        f"steps, PCG iterations/step mean {res_c.corot_iterations.mean():.1f}"
    )
    print(f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
