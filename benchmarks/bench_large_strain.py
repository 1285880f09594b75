"""The inverse step at one frame under the linear law and under the large-strain law.

Issue #32's jaw drops: the linear law turns lip tets inside out to follow the captured lip's
stretch (docs/VALIDATION.md). This fits one frame's actuation (stage ``actuate``'s inputs:
the captured scan's skin nodes, targets and weights, the skull held and the mandible turned;
its stress basis and per-patch stress costs; no rate cost and no Huber reweighting, which
couple or reweight frames) twice:

- linear: the static linear FEM at the basis material, one least-squares solve;
- large strain: :mod:`physanim.fem.hyperelastic` (isochoric neo-Hookean, averaged nodal
  pressure on ln J), with the coefficients as an active stress in the material frame or as
  an active strain, by Levenberg-Marquardt on the coefficients, each trial solved to
  equilibrium by Newton's method, with the targets taken from the passive equilibrium (the
  conditions alone) to the capture in continuation steps (halved where a step fails).

Other rows (``--rows``): each form under the linear fit's actuation (loaded in steps, each
halved where Newton's method fails; ``targets_reached`` is the share of the load reached),
and the bound of any law on this mesh: the node displacements that carry the captured scan's
motion best through its embedding in the tets (least squares). With ``--warm K``, the K
frames after the active strain's fit, each fitted from the frame before (its actuation and
shape, the targets taken in one step): what a fit over a performance would cost per frame.

For each: the fit's residual (relative displacement error of the skin against the captured
scan, moving skin only, as stage ``actuate`` reports it), with a ground truth its error
against the actor's true motion as stage ``evaluate`` measures it (its sample of scan
vertices, moved through their embedding in the tets) beside the captured scan's own (issue
#32 asks the FEM to be within 0.03 of it), tets inside out, the smallest volume ratio J, the
RMS actuation (kPa), the seconds, the tets stretched or shortened by more than
``STRETCHED`` along some direction with the nodes of the tets that touch them (the region a
large-strain law confined to where the tissue strains largely would cover); and the tets
where the linear fit's active stress is beyond the active stress's limit (a compression
larger than the shear modulus along some direction: there nothing in the tet resists a
stretch, module docstring of :mod:`physanim.fem.hyperelastic`). The frame is the one whose
stored fit (stage ``actuate``) turns the most tets inside out, unless given. A large-strain
fit takes minutes (each trial a few Newton steps on the whole mesh): the benchmark measures
whether that law can follow the capture, not a product cost.

Run: .venv/bin/python benchmarks/bench_large_strain.py [--dataset demo] [--frame F]
[--rows mesh_bound linear stress_held stress_fitted strain_held strain_fitted]
[--warm K] [--set key=value]... (default rows: mesh_bound linear strain_fitted, about 7 min on
2 cores with MKL's PARDISO, longer with SuperLU)
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp
from results import Table, describe, record  # benchmarks/results.py, beside this script

from flows.dags import FACE
from physanim.config import load_config
from physanim.evaluate.face import EvaluateParams, scan_sample
from physanim.evaluate.fidelity import face_regions, follow_truth, motion_fidelity
from physanim.evaluate.truth import load_truth
from physanim.fem.actuation import DEVIATORIC
from physanim.fem.geometry import node_dofs
from physanim.fem.hyperelastic import (
    ACTUATIONS,
    NeoHookeanANP,
    NotConverged,
    solve_static_large_strain,
    tensors,
)
from physanim.fem.linsolve import SymmetricFactors, factorize
from physanim.fem.statics import free_dofs
from physanim.mesh.embed import embedding_matrix
from physanim.pipeline import stage_inputs
from physanim.pipeline.progress import rich_progress
from physanim.pipeline.spec import dataset_overrides
from tasks.actuation import ActuateParams, fit_inputs, inverse_step

#: continuation: first step of the targets' share, smallest step before giving up
FIRST_STEP, SMALLEST_STEP = 0.2, 0.0125
#: Levenberg-Marquardt iterations per continuation step (more at the last), Newton's per trial
LM_ITERATIONS, LM_LAST, NEWTON_ITERATIONS = 3, 8, 10
#: relative gain of the objective below which a continuation step's iterations stop
LM_GAIN = 1e-3
#: a principal stretch this far from 1 counts as large strain (``stretched``)
STRETCHED = 0.2
STRETCHED_KEY = f"tets_stretched_over_{round(100 * STRETCHED)}_percent"


class FrameFit:
    """One frame's objective: the weighted mean square misfit of the ``observed`` nodes'
    DOFs ``rows`` (3S,) to ``targets`` (3S,) m plus lambda sum_i u_i a_i^2 (the inverse
    step's stress penalty without its rate term)."""

    def __init__(self, rows, targets, weights, penalty, lam):
        self.rows, self.y = rows, targets
        self.w = np.repeat(weights / weights.sum(), 3)
        self.u, self.lam = penalty, lam

    def value(self, d: np.ndarray, a: np.ndarray) -> float:
        r = d[self.rows] - self.y
        return float(self.w @ r**2 + self.lam * self.u @ a**2)

    def step(self, d, a, sensitivity, damping) -> np.ndarray:
        """The Levenberg-Marquardt step of the coefficients for d(a) ~ d + sensitivity da."""
        r = d[self.rows] - self.y
        A = (sensitivity * self.w[:, None]).T @ sensitivity
        A[np.diag_indices_from(A)] += (self.lam + damping) * self.u
        return -np.linalg.solve(A, sensitivity.T @ (self.w * r) + self.lam * self.u * a)


def linear_fit(model, basis, pres, values, fit: FrameFit):
    """The linear law's minimiser: coefficients (5P,) Pa and displacements (3N,) m."""
    free = free_dofs(model.n_dofs, pres)
    solve = factorize(model.K[free][:, free].tocsc())
    forces = basis.force_matrix(model)[free]
    at = np.searchsorted(free, fit.rows)
    R = solve(forces.toarray())
    d = np.zeros(model.n_dofs)
    d[pres] = values
    d[free] = solve(-(model.K[free][:, pres] @ values))
    a = fit.step(d, np.zeros(forces.shape[1]), R[at], 0.0)
    d[free] += R @ a
    return a, d


def large_strain_fit(law, basis, pres, values, fit: FrameFit, log, start=None):
    """The large-strain law's fit by continuation (module docstring), or from ``start`` (the
    coefficients and equilibrium of the frame before, moved to this frame's conditions under
    those coefficients, then its skin taken to this frame's targets in one step, halved where
    it fails): coefficients, the equilibrium, the share of the
    targets reached and the Newton iterations taken."""
    model = law.model
    free = free_dofs(model.n_dofs, pres)
    at = np.searchsorted(free, fit.rows)
    d, newton, factors = np.zeros(model.n_dofs), 0, SymmetricFactors()
    if start is None:
        for share in np.linspace(0.25, 1.0, 4):  # the conditions alone, in steps
            d, its = solve_static_large_strain(law, pres, share * values, start=d, factors=factors)
            newton += its
        a = np.zeros(basis.size)
    else:  # the frame before's actuation held while the conditions move to this frame's
        a, d = (np.array(x) for x in start)
        d, _, its = held(law, basis, pres, values, a, log, steps=1, start=(a, d))
        newton += its
    full, passive = fit.y.copy(), d[fit.rows].copy()
    step = FIRST_STEP if start is None else 1.0
    reached, damping = 0.0, 1e-3 * fit.lam
    while reached < 1.0 and step >= SMALLEST_STEP:
        share = min(1.0, reached + step)
        fit.y = passive + share * (full - passive)
        saved, current, failed, accepted = (a, d), fit.value(d, a), False, 0
        for _ in range(LM_LAST if share == 1.0 else LM_ITERATIONS):
            stress = basis.stress(a.reshape(-1, len(DEVIATORIC)))
            _, H = law.gradient(d, active=stress, hessian=True)
            solve = factors(H[free][:, free])
            forces = basis.force_matrix(model, law.nominal_per_direction(d, stress))[free]
            sens = solve(forces.toarray())
            while True:
                da = fit.step(d, a, sens[at], damping)
                trial = d.copy()
                trial[free] += sens @ da
                try:
                    stress = basis.stress((a + da).reshape(-1, len(DEVIATORIC)))
                    moved, its = solve_static_large_strain(
                        law, pres, values, active=stress, start=law.toward(d, trial),
                        max_iter=NEWTON_ITERATIONS, factors=factors,
                    )  # fmt: skip
                    newton += its
                    value = fit.value(moved, a + da)
                except NotConverged:
                    value = np.inf
                if value < current:
                    gain = (current - value) / current
                    a, d, current = a + da, moved, value
                    damping = max(damping / 3, 1e-6 * fit.lam)
                    accepted += 1
                    break
                damping *= 4
                if damping > 1e4 * fit.lam:
                    failed = True
                    break
            if failed or gain < LM_GAIN:
                break
        if failed and not accepted:
            a, d = saved
            step /= 2
            damping = 1e-3 * fit.lam
            log(f"  share {share:.3f}: no step; continuation step halved to {step:.4f}")
            continue
        reached = share
        log(
            f"  share {share:.3f}: objective {current:.3e}, min J {law.deformation(d)[1].min():.3f}"
        )
    fit.y = full
    return a, d, reached, newton


def held(law, basis, pres, values, a, log, steps=8, start=None):
    """The large-strain equilibrium (3N,) m under the coefficients ``a`` (5P,) Pa and the
    prescribed ``values``, loaded from the rest, or from ``start`` (coefficients and the
    equilibrium under them), in ``steps`` (halved where a step fails, doubled again after
    one that converges); the share of the load reached, Newton iterations."""
    n = law.model.n_dofs
    a0, d = (np.zeros_like(a), np.zeros(n)) if start is None else (np.array(x) for x in start)
    v0, reached, newton, step = d[pres].copy(), 0.0, 0, 1.0 / steps
    while reached < 1.0 and step >= SMALLEST_STEP / 8:
        share = min(1.0, reached + step)
        stress = basis.stress((a0 + share * (a - a0)).reshape(-1, len(DEVIATORIC)))
        try:
            d, its = solve_static_large_strain(
                law, pres, v0 + share * (values - v0), active=stress, start=d,
                max_iter=2 * NEWTON_ITERATIONS,
            )  # fmt: skip
        except NotConverged:
            step /= 2
            log(f"  load {share:.3f}: Newton did not converge; load step halved to {step:.4f}")
            continue
        reached, newton, step = share, newton + its, min(2 * step, 1.0 / steps)
        log(f"  load {share:.3f}: {its} Newton iterations, min J {law.deformation(d)[1].min():.3f}")
    return d, reached, newton


def stretched(law, d, over=STRETCHED) -> tuple[int, int]:
    """Tets (count) stretched or shortened by more than ``over`` (a share) along some direction
    at d (3N,) m, and the nodes of the tets that touch them: the region a large-strain law
    confined to where the tissue strains largely would have to cover."""
    F, _ = law.deformation(d)
    tets = law.model.tets
    far = np.abs(np.linalg.svd(F, compute_uv=False) - 1).max(axis=1) > over
    touching = np.isin(tets, tets[far]).any(axis=1)
    return int(far.sum()), len(np.unique(tets[touching]))


def beyond_limit(model, stress) -> int:
    """Tets (count) whose active stress (M, 6) Pa compresses some direction by more than the
    tet's shear modulus."""
    smallest = np.linalg.eigvalsh(tensors(stress))[:, 0]
    return int((smallest < -model.mu).sum())


def against_truth(config, align, dense, tetra, frame):
    """Stage ``evaluate``'s motion fidelity at ``frame`` on its sample of scan vertices, moved
    through their embedding in the tets: a function of node displacements (3N,) m, and the
    captured scan's own figure; (None, None) without a ground truth."""
    params = config.section("evaluate", EvaluateParams)
    path = config.dataset.path / params.truth
    if not path.exists():
        return None, None
    scan_v = align.scan_vertices
    ids, labels = scan_sample(scan_v, align.landmark_positions(), params.error_max_points)
    truth = load_truth(path, frame + 1)
    true = follow_truth(scan_v[ids], truth.vertices, truth.faces, params.closest_points)
    on = true.on_truth(params.truth_max_distance_m)  # as evaluate: filled holes have no truth
    ids, labels, true_u = ids[on], labels[on], true.displacement[frame, on]
    W = _embedding(align, tetra, ids)

    def fidelity(moved: np.ndarray) -> float:
        return float(motion_fidelity(moved[None], true_u[None], labels).overall[0])

    captured = np.asarray(dense.motion[frame], dtype=np.float64)[ids] - scan_v[ids]
    return (lambda d: fidelity(W @ d.reshape(-1, 3))), fidelity(captured)


def _embedding(align, tetra, ids=None):
    """The embedding (S, n) of the scan's vertices ``ids`` (default all) in the tets."""
    ids = np.arange(len(align.scan_vertices)) if ids is None else ids
    side = align.mouth().element_side(tetra.nodes, tetra.tets)
    points = align.scan_vertices[ids]
    return sp.csr_matrix(
        embedding_matrix(points, align.scan_side[ids], tetra.nodes, tetra.tets, side)
    )


def mesh_bound(align, dense, tetra, model, frame, weight=1e-3):
    """The node displacements (3N,) m that carry the captured scan's motion at ``frame`` best
    through its embedding in the tets (least squares over all its vertices, plus ``weight``
    times the elastic energy, scaled, which places the nodes no vertex sees): what any drive of
    this mesh, whatever its law, can at best do."""
    W = sp.kron(_embedding(align, tetra), sp.identity(3), format="csr")
    captured = np.asarray(dense.motion[frame], dtype=np.float64) - align.scan_vertices
    A = (W.T @ W).tocsc()
    K = model.K * (abs(A).max() / abs(model.K).max())
    return factorize((A + weight * K).tocsc(), "superlu")(W.T @ captured.ravel())


def measure(
    dataset_arg: str, frame: int | None, keys: list[str], overrides: list[str], warm: int = 0
) -> list[list]:
    """Rows (``COLUMNS``) of one dataset's frame for the laws ``keys`` (``ROWS``), and with
    ``strain_fitted`` the ``warm`` frames after it, each fitted from the one before."""
    config, _ = load_config(
        FACE.config_model(), [FACE.default_config], [*dataset_overrides(dataset_arg), *overrides]
    )
    with rich_progress() as progress:
        inputs = stage_inputs(FACE, config, "actuate", progress)
    params: ActuateParams = FACE.stage("actuate").params_from(config)
    track, align, dense, tetra = (inputs[k] for k in ("track", "align", "dense", "tetra"))
    fin = fit_inputs(params, track, align, dense, tetra)
    landmarks = align.landmark_positions()
    step = inverse_step(
        params, tetra, fin.conditions, fin.observed, fin.targets, fin.weights, landmarks
    )
    model, basis, n = step.model, step.basis, fin.n_captured
    law = NeoHookeanANP(model)  # the active stress, for the frame's choice and J
    pres = fin.conditions.prescribed_dofs
    values = fin.conditions.prescribed(fin.conditions.frame_dt * np.arange(len(fin.targets)))[0]
    if frame is None:  # the stored fit's frame with the most tets inside out
        free = free_dofs(model.n_dofs, pres)
        solve = factorize(model.K[free][:, free].tocsc())
        rhs = (basis.force_matrix(model)[free] @ step.fit.coefficients.reshape(len(values), -1).T
               - model.K[free][:, pres] @ values.T)  # fmt: skip
        d_all = np.zeros((model.n_dofs, len(values)))
        d_all[pres], d_all[free] = values.T, solve(rhs)
        inverted = [int((law.deformation(d_all[:, t])[1] <= 0).sum()) for t in range(len(values))]
        frame = int(np.argmax(inverted))
        print(f"{dataset_arg}: frame {frame}, {inverted[frame]} tets inside out in the stored fit")
    vol = basis.patch_volumes(model.volumes)
    penalty = np.repeat(vol / vol.sum() * step.patch_cost**2, len(DEVIATORIC))
    lam = (params.actuation.stress_cost_mm_per_kPa * 1e-6) ** 2
    rows_all = node_dofs(fin.observed).ravel()
    labels = face_regions(tetra.nodes[fin.observed[:n]], landmarks)

    def frame_fit(f):
        return FrameFit(rows_all, fin.targets[f].ravel(), fin.weights[f], penalty, lam)

    def row(name, f, a, d, reached, newton, seconds, truth_of):
        fem_vs_truth, captured = truth_of
        skin = d[rows_all].reshape(-1, 3)[:n]
        residual = motion_fidelity(skin[None], fin.targets[f, :n][None], labels).overall[0]
        J = law.deformation(d)[1]
        rms = float(np.sqrt(penalty @ a**2 / penalty.sum())) / 1e3
        truth = None if fem_vs_truth is None else fem_vs_truth(d)
        far, region = stretched(law, d)
        print(f"{dataset_arg} frame {f}, {name}: residual {residual:.4f}, truth {truth}, "
              f"{int((J <= 0).sum())} tets inside out, min J {J.min():.3f}, RMS stress "
              f"{rms:.1f} kPa, targets reached {reached:.3f}, {seconds:.0f} s; {far} of "
              f"{len(J)} tets stretched by more than {STRETCHED:.0%}, {region} of "
              f"{len(tetra.nodes)} nodes in them and the tets touching them")  # fmt: skip
        return [dataset_arg, f, name, float(residual), truth, captured, int((J <= 0).sum()),
                float(J.min()), rms, reached, newton, seconds, beyond, far, region]  # fmt: skip

    fit = frame_fit(frame)
    truth_of = against_truth(config, align, dense, tetra, frame)
    print(f"{dataset_arg} frame {frame}: the captured motion's error against the truth "
          f"{truth_of[1]}")  # fmt: skip
    out, beyond = [], None
    for key in ["linear", *(k for k in ROWS if k in keys and k != "linear")]:
        name, form = ROWS[key], key.split("_")[0]
        t0 = time.perf_counter()
        if key == "mesh_bound":
            a, reached, newton = np.zeros(basis.size), 1.0, 0
            d = mesh_bound(align, dense, tetra, model, frame)
        elif key == "linear":
            a, d = linear_fit(model, basis, pres, values[frame], fit)
            a_linear, reached, newton = a, 1.0, 0
            stress = basis.stress(a.reshape(-1, len(DEVIATORIC)))
            beyond = beyond_limit(model, stress)
            print(f"{dataset_arg} frame {frame}: the linear fit's active stress is beyond its "
                  f"limit in {beyond} of {len(model.tets)} tets")  # fmt: skip
        elif key.endswith("fitted"):
            a, d, reached, newton = large_strain_fit(
                NeoHookeanANP(model, form), basis, pres, values[frame], fit, print
            )
        else:
            form_law = NeoHookeanANP(model, form)
            a, d, reached, newton = (
                a_linear,
                *held(form_law, basis, pres, values[frame], a_linear, print),
            )
        out.append(row(name, frame, a, d, reached, newton, time.perf_counter() - t0, truth_of))
        if key == "strain_fitted":
            fitted = (a, d)
    for f in (
        range(frame + 1, min(frame + 1 + warm, len(values))) if "strain_fitted" in keys else ()
    ):
        t0 = time.perf_counter()
        a, d, reached, newton = large_strain_fit(
            NeoHookeanANP(model, "strain"), basis, pres, values[f], frame_fit(f), print, fitted
        )
        seconds, fitted = time.perf_counter() - t0, (a, d)
        truth_f = against_truth(config, align, dense, tetra, f)
        out.append(row(WARM, f, a, d, reached, newton, seconds, truth_f))
    return out


COLUMNS = ["dataset", "frame", "law", "residual", "error_vs_truth", "captured_error_vs_truth",
           "inverted_tets", "min_J", "rms_stress_kPa", "targets_reached", "newton_iterations",
           "seconds", "linear_fit_tets_beyond_stress_limit", STRETCHED_KEY,
           "nodes_of_the_stretched_tets_and_their_neighbours"]  # fmt: skip
#: the rows: key -> the law's name (the linear fit always runs: the others start from it)
ROWS = {
    "mesh_bound": "least squares to the captured scan (any law's bound on this mesh)",
    "linear": "linear",
    **{
        f"{form}_{how}": f"active {form}, {text}"
        for form in ACTUATIONS
        for how, text in (("held", "the linear fit's actuation"), ("fitted", "fitted"))
    },
}


#: what ``make bench`` measures (about 7 min on 2 cores): the other rows take as long and
#: stall or miss the capture (docs/VALIDATION.md)
DEFAULT_ROWS = ["mesh_bound", "linear", "strain_fitted"]


#: the rows of the frames after, each fitted from the one before (``--warm``)
WARM = "active strain, fitted from the frame before"


def _key(row: list) -> str:
    """The headline key of a row: its ``ROWS`` key, or strain_warm_<frame>."""
    if row[2] == WARM:
        return f"strain_warm_{row[1]}"
    return next(k for k, v in ROWS.items() if v == row[2])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--dataset", default="demo", help="dataset name (data/<name>) or folder")
    ap.add_argument("--frame", type=int, default=None, help="capture frame (default: above)")
    ap.add_argument("--rows", nargs="+", default=DEFAULT_ROWS, choices=list(ROWS),
                    help=f"the laws to measure (default: {' '.join(DEFAULT_ROWS)})")  # fmt: skip
    ap.add_argument(
        "--warm", type=int, default=0, help="with strain_fitted: the frames after it to fit, "
        "each from the one before",
    )  # fmt: skip
    ap.add_argument("--set", action="append", default=[], help="a config override key=value")
    args = ap.parse_args()
    rows = measure(args.dataset, args.frame, args.rows, args.set, args.warm)
    record(
        "bench_large_strain",
        [
            Table(
                "one frame's actuation fitted under the linear and the large-strain law",
                COLUMNS,
                rows,
                notes="residual: relative displacement error of the fitted skin against the "
                "captured scan (moving skin); stress penalty as stage actuate's, no rate cost",
            )
        ],
        **describe(__doc__, "bench_large_strain"),
        headline={_key(r) + "_residual": r[3] for r in rows}
        | {_key(r) + "_error_vs_truth": r[4] for r in rows}
        | {_key(r) + "_inverted": r[6] for r in rows}
        | {_key(r) + "_targets_reached": r[9] for r in rows}
        | {_key(r) + "_seconds": r[11] for r in rows if r[2] == WARM}
        | {"captured_error_vs_truth": rows[0][5]}
        | {"linear_fit_tets_beyond_stress_limit": rows[0][12]}
        | {_key(r) + "_" + STRETCHED_KEY: r[13] for r in rows},
    )


if __name__ == "__main__":
    main()
