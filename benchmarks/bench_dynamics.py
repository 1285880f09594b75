"""Forward-dynamics time per step (2-link arm and 30-DOF human), compiled kernels vs a
plain-numpy reference (loop over bodies, vectorised over the H columns) in the same run.

Run: .venv/bin/python benchmarks/bench_dynamics.py
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from physanim.dynamics import Figure, forward_dynamics

CONFIGS = Path(__file__).resolve().parents[1] / "configs" / "figures"
G = np.array([0.0, -9.81, 0.0])


def _rodrigues(axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(B, 3, 3) rotations about a unit axis (3,) by angles q (B,)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    c, s = np.cos(q)[:, None, None], np.sin(q)[:, None, None]
    return np.eye(3) + s * k + (1 - c) * (k @ k)


def rnea_numpy(fig: Figure, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, a0: np.ndarray):
    """Reference Newton-Euler in plain numpy: q, qd, qdd (B, n); a0 (B, 3) -> tau (B, n)."""
    nb, n = q.shape
    rot, pos = np.zeros((n, nb, 3, 3)), np.zeros((n, nb, 3))
    w, al, acc = np.zeros((n, nb, 3)), np.zeros((n, nb, 3)), np.zeros((n, nb, 3))
    f, mo, z = np.zeros((n, nb, 3)), np.zeros((n, nb, 3)), np.zeros((n, nb, 3))
    for i in range(n):
        p = fig.parent[i]
        rp = np.broadcast_to(np.eye(3), (nb, 3, 3)) if p < 0 else rot[p]
        pp = np.zeros((nb, 3)) if p < 0 else pos[p]
        wp = np.zeros((nb, 3)) if p < 0 else w[p]
        ap = np.zeros((nb, 3)) if p < 0 else al[p]
        lp = a0 if p < 0 else acc[p]
        rot[i] = rp @ _rodrigues(fig.axis[i], q[:, i])
        pos[i] = pp + rp @ fig.offset[i]
        r = pos[i] - pp
        z[i] = rot[i] @ fig.axis[i]
        acc[i] = lp + np.cross(ap, r) + np.cross(wp, np.cross(wp, r))
        w[i] = wp + z[i] * qd[:, i, None]
        al[i] = ap + z[i] * qdd[:, i, None] + np.cross(wp, z[i] * qd[:, i, None])
        c = rot[i] @ fig.com[i]
        fc = fig.mass[i] * (acc[i] + np.cross(al[i], c) + np.cross(w[i], np.cross(w[i], c)))
        iw = rot[i] @ fig.inertia[i] @ np.swapaxes(rot[i], 1, 2)
        f[i] = fc
        mo[i] = (iw @ al[i][..., None])[..., 0] + np.cross(w[i], (iw @ w[i][..., None])[..., 0])
        mo[i] += np.cross(c, fc)
    tau = np.zeros((nb, n))
    for i in range(n - 1, -1, -1):
        tau[:, i] = np.einsum("bk,bk->b", z[i], mo[i])
        p = fig.parent[i]
        if p >= 0:
            f[p] += f[i]
            mo[p] += mo[i] + np.cross(pos[i] - pos[p], f[i])
    return tau


def forward_numpy(fig: Figure, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Seed method in plain numpy: bias and all H columns in one batched RNEA call."""
    n = fig.n_dof
    qs = np.vstack([q, np.broadcast_to(q, (n, n))])
    qds = np.vstack([qd, np.zeros((n, n))])
    qdds = np.vstack([np.zeros(n), np.eye(n)])
    a0 = np.vstack([-G, np.zeros((n, 3))])
    out = rnea_numpy(fig, qs, qds, qdds, a0)
    return np.linalg.solve(out[1:].T, -out[0])


def _time(fn, reps: int) -> float:
    fn()
    t0 = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t0) / reps


def main() -> None:
    rng = np.random.default_rng(0)
    print(
        f"{'figure':10s} {'DOF':>4s} {'numpy ref':>12s} {'seed (numba)':>13s} "
        f"{'CRBA (numba)':>13s} {'speed-up':>9s} {'max |dqdd|':>11s}"
    )
    for name in ("arm2", "human30"):
        fig = Figure.from_yaml(CONFIGS / f"{name}.yaml")
        q, qd = rng.uniform(-0.5, 0.5, fig.n_dof), rng.normal(size=fig.n_dof)
        ref = forward_numpy(fig, q, qd)
        err = max(
            np.abs(forward_dynamics(fig, q, qd, method=m) - ref).max() for m in ("rnea", "crba")
        )
        t_np = _time(lambda fig=fig, q=q, qd=qd: forward_numpy(fig, q, qd), 50)
        t_rn = _time(lambda fig=fig, q=q, qd=qd: forward_dynamics(fig, q, qd, method="rnea"), 500)
        t_cr = _time(lambda fig=fig, q=q, qd=qd: forward_dynamics(fig, q, qd, method="crba"), 500)
        print(
            f"{name:10s} {fig.n_dof:4d} {t_np * 1e3:9.3f} ms {t_rn * 1e3:10.3f} ms "
            f"{t_cr * 1e3:10.3f} ms {t_np / min(t_rn, t_cr):8.1f}x {err:11.2e}"
        )


if __name__ == "__main__":
    main()
