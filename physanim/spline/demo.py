"""Seed 002's figure-eight demo: data, the four samplings and plots like its figures 1, 3-6."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure as MplFigure

from physanim.spline.cubic import Spline, natural_spline
from physanim.spline.sampling import sample


def figure_eight_points(n: int = 19, width: float = 1.0, height: float = 0.5) -> np.ndarray:
    """n points (n, 2) m on x = width sin u, y = height sin 2u; points 1, (n+1)/2 and n
    coincide at the crossing (seed: 19 points, 1, 10 and 19 equal)."""
    u = np.linspace(0.0, 2.0 * np.pi, n)
    p = np.c_[width * np.sin(u), height * np.sin(2.0 * u)]
    p[[0, n // 2, n - 1]] = 0.0
    return p


def figure_eight_spline() -> Spline:
    """Natural spline through the 19 points plus the seed's 20th point (= P_2)."""
    p = figure_eight_points()
    return natural_spline(p, extra_point=p[1])


def cos_rule(count: int = 43) -> np.ndarray:
    """Seed's user rule: increments |cos(pi i / 21)|, i = 1..count-1."""
    return np.abs(np.cos(np.pi * np.arange(1, count) / 21.0))


def plot_demo(out_dir: str | Path) -> dict[str, Path]:
    """Write fig1 (K along the curve), fig3 (spline and data), fig4 (41 equal-arc),
    fig5 (41 curvature-spaced) and fig6 (43 |cos|-rule samples) as PNGs."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sp = figure_eight_spline()
    data = figure_eight_points()
    t = np.linspace(0.0, sp.t_end, 1000)
    curve = sp(t)
    paths: dict[str, Path] = {}

    fg = MplFigure(figsize=(6, 3.5), dpi=100)
    ax = fg.subplots()
    ax.plot(sp.arc_length(t), sp.curvature_proxy(t))
    ax.set_xlabel("arc length from P1 (m)")
    ax.set_ylabel("K = |P''(t)| (1/m)")
    ax.set_title("Fig. 1: curvature proxy along the spline")
    fg.tight_layout()
    paths["fig1"] = out / "fig1_curvature.png"
    fg.savefig(paths["fig1"])

    panels = {
        "fig3": ("Fig. 3: natural spline through 19 points (+ extra point)", None),
        "fig4": ("Fig. 4: 41 equal-arc-length samples", sample(sp, "arc", 41)[0]),
        "fig5": ("Fig. 5: 41 samples, equal integral of K", sample(sp, "curvature", 41)[0]),
        "fig6": ("Fig. 6: 43 samples, |cos(pi i/21)| rule", sample(sp, cos_rule())[0]),
    }
    for key, (title, pts) in panels.items():
        fg = MplFigure(figsize=(6, 3.8), dpi=100)
        ax = fg.subplots()
        ax.plot(curve[:, 0], curve[:, 1], "-", color="0.6", lw=1)
        if pts is None:
            ax.plot(data[:, 0], data[:, 1], "kx", ms=7, label="data")
            extra = sp(np.array([sp.knots[-1]]))
            ax.plot(extra[:, 0], extra[:, 1], "rs", mfc="none", label="extra point")
            ax.legend(fontsize=8)
        else:
            ax.plot(pts[:, 0], pts[:, 1], "k+", ms=8)
            for i in (0, len(pts) // 2, len(pts) - 1):
                ax.annotate(
                    str(i + 1), pts[i], textcoords="offset points", xytext=(4, 4), fontsize=7
                )
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(title, fontsize=10)
        fg.tight_layout()
        paths[key] = out / f"{key}.png"
        fg.savefig(paths[key])
    return paths


if __name__ == "__main__":
    import sys

    target = Path(sys.argv[1] if len(sys.argv) > 1 else "out/spline_demo")
    for name, written in plot_demo(target).items():
        print(f"{name}: {written}")
