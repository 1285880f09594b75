"""Forward dynamics per call (2-link arm and 30-DOF human) against Pinocchio's ABA and
MuJoCo's mj_forward, measured side by side in the same run (the ``refs`` extra).
Columns: physanim ABA (the default), CRBA + Newton-Euler bias + solve, the seed's method
(H column by column from inverse dynamics), Pinocchio ``aba``, MuJoCo ``mj_forward`` (the
whole forward pass), the ratio ABA / Pinocchio and the largest disagreement with Pinocchio.

Each time is the median over 40 blocks of 250 calls through each library's Python API
(inputs already arrays).  Targets: physanim ``forward_dynamics`` (ABA) within 2x of
Pinocchio on the human and within 5x on the arm.

Run: .venv/bin/python benchmarks/bench_dynamics.py
"""

from __future__ import annotations

import time
from pathlib import Path

import mujoco
import numpy as np
import pinocchio as pin
from results import Table, describe, record  # benchmarks/results.py, beside this script

from physanim.dynamics import Figure, forward_dynamics, inverse_dynamics
from physanim.dynamics.reference_models import mujoco_model, pinocchio_model

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "figures"
TARGET = {"arm2": 5.0, "human30": 2.0}  # allowed ratio physanim ABA / Pinocchio ABA


def _median_us(fn, block: int = 250, blocks: int = 40) -> float:
    """Median time per call (us) over ``blocks`` blocks of ``block`` calls."""
    for _ in range(block):
        fn()
    times = []
    for _ in range(blocks):
        t0 = time.perf_counter()
        for _ in range(block):
            fn()
        times.append((time.perf_counter() - t0) / block)
    return float(np.median(times)) * 1e6


def _figure_row(name: str, rng: np.random.Generator) -> tuple[str, list]:
    """One table row, printed and recorded: per-call times (us), the ratio to Pinocchio and the
    largest disagreement."""
    fig = Figure.from_yaml(CONFIGS / f"{name}.yaml")
    q = rng.uniform(-0.5, 0.5, fig.n_dof)
    qd, tau = rng.normal(size=fig.n_dof), rng.normal(size=fig.n_dof)
    pm = pinocchio_model(fig)
    pd = pm.createData()
    mm = mujoco_model(fig)
    md = mujoco.MjData(mm)
    md.qpos[:], md.qvel[:], md.qfrc_applied[:] = q, qd, tau
    mujoco.mj_forward(mm, md)
    ref = pin.aba(pm, pd, q, qd, tau)
    err = max(
        np.abs(forward_dynamics(fig, q, qd, tau, method=m) - ref).max()
        for m in ("aba", "crba", "rnea")
    )
    err = max(err, float(np.abs(md.qacc - ref).max()))
    t = {
        "aba": _median_us(lambda: forward_dynamics(fig, q, qd, tau)),
        "crba": _median_us(lambda: forward_dynamics(fig, q, qd, tau, method="crba")),
        "rnea": _median_us(lambda: forward_dynamics(fig, q, qd, tau, method="rnea")),
        "pin": _median_us(lambda: pin.aba(pm, pd, q, qd, tau)),
        "mj": _median_us(lambda: mujoco.mj_forward(mm, md)),
    }
    ratio = t["aba"] / t["pin"]
    verdict = "ok" if ratio <= TARGET[name] else "MISSED"
    cells = [name, fig.n_dof, *(t[k] for k in ("aba", "crba", "rnea", "pin", "mj"))]
    cells += [ratio, TARGET[name], err, verdict]
    text = (
        f"{name:8s} {fig.n_dof:3d} {t['aba']:6.2f}us {t['crba']:6.2f}us {t['rnea']:6.2f}us "
        f"{t['pin']:8.2f}us {t['mj']:6.2f}us {ratio:7.2f}x {TARGET[name]:5.0f}x "
        f"{err:11.2e} {verdict}"
    )
    return text, cells


def main() -> None:
    rng = np.random.default_rng(0)
    print(
        f"{'figure':8s} {'DOF':>3s} {'ABA':>8s} {'CRBA':>8s} {'seed':>8s} "
        f"{'Pinocchio':>10s} {'MuJoCo':>8s} {'ABA/pin':>8s} {'target':>7s} {'max |dqdd|':>11s}"
    )
    rows = []
    for name in ("arm2", "human30"):
        text, cells = _figure_row(name, rng)
        print(text)
        rows.append(cells)
    # batched inverse dynamics over a trajectory (one call) against a Pinocchio loop
    fig = Figure.from_yaml(CONFIGS / "human30.yaml")
    pm = pinocchio_model(fig)
    pd = pm.createData()
    q, qd, qdd = (rng.normal(size=(1000, fig.n_dof)) for _ in range(3))
    t_ours = _median_us(lambda: inverse_dynamics(fig, q, qd, qdd), block=2, blocks=15)
    t_pin = _median_us(
        lambda: [pin.rnea(pm, pd, a, b, c) for a, b, c in zip(q, qd, qdd, strict=True)],
        block=2,
        blocks=15,
    )
    print(
        f"inverse dynamics, 1000 poses of human30: physanim {t_ours / 1e3:.2f} ms (one call), "
        f"Pinocchio rnea loop {t_pin / 1e3:.2f} ms"
    )
    columns = ["figure", "dof", "aba_us", "crba_us", "seed_us", "pinocchio_us", "mujoco_us"]
    columns += ["aba_over_pinocchio", "target", "max_abs_dqdd_rad_s2", "verdict"]
    batched = [["physanim, one call", t_ours / 1e3], ["Pinocchio rnea loop", t_pin / 1e3]]
    record(
        "bench_dynamics",
        [
            Table("forward dynamics per call (medians of 40 x 250 calls)", columns, rows),
            Table(
                "batched inverse dynamics, 1000 poses of human30", ["implementation", "ms"], batched
            ),
        ],
        **describe(__doc__, "bench_dynamics"),
        headline={
            "human30_aba_us": rows[1][2],
            "human30_ratio": rows[1][7],
            "arm2_ratio": rows[0][7],
        },
    )


if __name__ == "__main__":
    main()
