"""Evaluation plots of the face pipeline (matplotlib, Agg canvas), each saved as PNG and SVG.

Inputs are SI (seconds, metres, joules); the axes show mm where the seed does.  Every
function takes ``stem`` (path without suffix) and returns ``(png_path, svg_path)``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib
import numpy as np
from matplotlib.figure import Figure as MplFigure

if TYPE_CHECKING:
    from physanim.evaluate.face import FaceEvaluation
    from physanim.face.jaw import JawMotion


def _save(fig: MplFigure, stem: str | Path) -> tuple[Path, Path]:
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    png, svg = stem.with_suffix(".png"), stem.with_suffix(".svg")
    fig.savefig(png, dpi=120)
    # no date and fixed element ids: the same figure gives the same bytes on every run
    with matplotlib.rc_context({"svg.hashsalt": stem.name}):
        fig.savefig(svg, metadata={"Date": None})
    return png, svg


def _check_series(time: np.ndarray, series: Mapping[str, np.ndarray], what: str) -> np.ndarray:
    time = np.asarray(time, dtype=np.float64)
    if time.ndim != 1:
        raise ValueError(f"time must be (T,) seconds, got shape {time.shape}")
    if not series:
        raise ValueError(f"{what}: nothing to plot (empty mapping)")
    for name, y in series.items():
        if len(np.asarray(y)) != len(time):
            raise ValueError(f"{what}[{name!r}] has {len(y)} samples, time has {len(time)}")
    return time


def plot_symmetry_cost(
    time: np.ndarray, costs: Mapping[str, np.ndarray], stem: str | Path
) -> tuple[Path, Path]:
    """Symmetry cost L(t) = ln|E_L - E_R| (SPEC eq 4.38, already a log) per variant;
    ``time`` (T,) s, ``costs`` name -> (T,) dimensionless."""
    time = _check_series(time, costs, "costs")
    fig = MplFigure(figsize=(7, 3.6))
    ax = fig.subplots()
    for k, (name, cost) in enumerate(costs.items()):
        ax.plot(time, cost, lw=1.5, color=f"C{k}", label=name)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(r"symmetry cost $\ln|E_L - E_R|$ (log scale)")
    ax.set_title("Symmetry cost (lower = more symmetric)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, stem)


def plot_mouth_corners(
    time: np.ndarray,
    corners: Mapping[str, np.ndarray],
    stem: str | Path,
    *,
    sides: Sequence[str] = ("left (ch_L)", "right (ch_R)"),
) -> tuple[Path, Path]:
    """Mouth-corner displacement |p(t) - p(0)| per variant (seed figure 6.9): ``corners``
    name -> (T, 2) m (columns: the actor's left and right cheilion); axes in mm vs s."""
    time = _check_series(time, corners, "corners")
    fig = MplFigure(figsize=(10, 3.6))
    axes = fig.subplots(1, len(sides), sharey=True, squeeze=False)[0]
    for k, (name, d) in enumerate(corners.items()):
        d = np.asarray(d, dtype=np.float64)
        if d.shape != (len(time), len(sides)):
            raise ValueError(
                f"corners[{name!r}] must be ({len(time)}, {len(sides)}) m, got {d.shape}"
            )
        for j, ax in enumerate(axes):
            ax.plot(time, 1e3 * d[:, j], lw=1.5, color=f"C{k}", label=name)
    for ax, side in zip(axes, sides, strict=True):
        ax.set_title(f"mouth corner, {side}")
        ax.set_xlabel("time (s)")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("displacement (mm)")
    axes[0].legend(fontsize=8)
    return _save(fig, stem)


def plot_energies(
    time: np.ndarray, energies: Mapping[str, Mapping[str, np.ndarray]], stem: str | Path
) -> tuple[Path, Path]:
    """One panel per energy (e.g. kinetic, strain, dissipated), one line per variant:
    ``energies`` variant -> quantity -> (T,) J; ``time`` (T,) s."""
    if not energies:
        raise ValueError("energies: nothing to plot (empty mapping)")
    quantities = list(dict.fromkeys(q for v in energies.values() for q in v))
    fig = MplFigure(figsize=(4 * len(quantities), 3.4))
    axes = fig.subplots(1, len(quantities), squeeze=False)[0]
    for k, (variant, series) in enumerate(energies.items()):
        time = _check_series(time, series, f"energies[{variant!r}]")
        for ax, q in zip(axes, quantities, strict=True):
            if q in series:
                ax.plot(time, series[q], lw=1.5, color=f"C{k}", label=variant)
    for ax, q in zip(axes, quantities, strict=True):
        ax.set_title(f"{q} energy")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("energy (J)")
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 3))
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return _save(fig, stem)


def plot_landmark_curves(
    time: np.ndarray,
    displacement: np.ndarray,
    names: Sequence[str],
    stem: str | Path,
    *,
    title: str = "Landmark displacement",
) -> tuple[Path, Path]:
    """|p_k(t) - p_k(0)| of every landmark: ``displacement`` (T, K) m, ``names`` (K,);
    bilateral pairs share a colour (left solid, right dashed); axes in mm vs s."""
    time = np.asarray(time, dtype=np.float64)
    d = np.asarray(displacement, dtype=np.float64)
    if d.shape != (len(time), len(names)):
        raise ValueError(f"displacement must be ({len(time)}, {len(names)}) m, got {d.shape}")
    bases = list(dict.fromkeys(n.removesuffix("_L").removesuffix("_R") for n in names))
    fig = MplFigure(figsize=(8, 4.2))
    ax = fig.subplots()
    for k, name in enumerate(names):
        base = name.removesuffix("_L").removesuffix("_R")
        colour = f"C{bases.index(base) % 10}"
        style = "--" if name.endswith("_R") else "-"
        ax.plot(time, 1e3 * d[:, k], style, lw=1.3, color=colour, label=name)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("displacement (mm)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return _save(fig, stem)


def plot_fidelity(
    time: np.ndarray,
    overall: Mapping[str, np.ndarray],
    regions: Mapping[str, np.ndarray],
    region_names: Sequence[str],
    stem: str | Path,
    *,
    peaks: Mapping[str, float] | None = None,
) -> tuple[Path, Path]:
    """Relative displacement error against the truth (0 = moves like the actor, 1 = does not
    move): the whole face, then one panel per region, one line per model.  ``overall``
    model -> (T,); ``regions`` model -> (T, R); ``peaks`` name -> time (s) marked by lines."""
    time = _check_series(time, overall, "overall")
    panels = ["whole face", *region_names]
    fig = MplFigure(figsize=(3.2 * len(panels), 3.4))
    axes = fig.subplots(1, len(panels), sharey=True, squeeze=False)[0]
    for k, (model, curve) in enumerate(overall.items()):
        series = [np.asarray(curve), *np.asarray(regions[model]).T]
        for ax, y in zip(axes, series, strict=True):
            ax.plot(time, y, lw=1.5, color=f"C{k}", label=model)
    for ax, title in zip(axes, panels, strict=True):
        for name, t in (peaks or {}).items():
            ax.axvline(t, color="0.6", lw=0.8, ls=":")
            ax.text(t, 1.02, name, fontsize=7, ha="center", transform=ax.get_xaxis_transform())
        ax.set_title(title.replace("_", " & "), pad=14)
        ax.set_xlabel("time (s)")
        ax.set_ylim(0.0, 1.2)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("relative displacement error (-)")
    axes[0].legend(fontsize=8)
    return _save(fig, stem)


def plot_lip_gap(
    time: np.ndarray, gaps: Mapping[str, np.ndarray], stem: str | Path
) -> tuple[Path, Path]:
    """Distance between the upper and lower lip midline points per model (``gaps`` name ->
    (T,) m, e.g. truth, FEM, kinematic), in mm vs s."""
    time = _check_series(time, gaps, "gaps")
    fig = MplFigure(figsize=(7, 3.4))
    ax = fig.subplots()
    for k, (name, gap) in enumerate(gaps.items()):
        ax.plot(time, 1e3 * np.asarray(gap), lw=1.5, color=f"C{k}", label=name)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("lip gap (mm)")
    ax.set_title("Lip gap: upper to lower lip midline")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, stem)


def plot_jaw(
    time: np.ndarray, angle: np.ndarray, residual: np.ndarray, stem: str | Path
) -> tuple[Path, Path]:
    """Estimated jaw opening angle (T,) rad and the RMS misfit (T,) m of the mandible points
    about the fitted hinge, in degrees and mm vs s."""
    time = _check_series(time, {"angle": angle, "residual": residual}, "jaw")
    fig = MplFigure(figsize=(9, 3.2))
    a, b = fig.subplots(1, 2)
    a.plot(time, np.degrees(angle), lw=1.5, color="C0")
    a.set_title("Jaw opening about the estimated hinge")
    a.set_xlabel("time (s)")
    a.set_ylabel("angle (deg)")
    b.plot(time, 1e3 * np.asarray(residual), lw=1.5, color="C3")
    b.set_title("Misfit of the mandible points")
    b.set_xlabel("time (s)")
    b.set_ylabel("RMS residual (mm)")
    for ax in (a, b):
        ax.grid(alpha=0.3)
    return _save(fig, stem)


def plot_simulation(
    time: np.ndarray, energies: Mapping[str, np.ndarray], jaw: JawMotion | None, folder: Path
) -> None:
    """The simulation's plots into ``folder``: the FEM ``energies`` (name -> (T,) J) and the
    ``jaw`` (None: disabled); ``time`` (T,) s."""
    time = np.asarray(time)
    plot_energies(time, {"fem": energies}, folder / "energies")
    if jaw is not None:
        plot_jaw(time, jaw.angle, jaw.residual_m, folder / "jaw")


def plot_evaluation(time: np.ndarray, evaluation: FaceEvaluation, folder: Path) -> None:
    """The evaluation's plots into ``folder``: symmetry cost, mouth corners (tracked,
    kinematic, FEM) and, when the ``evaluation`` has a ground truth, fidelity and lip gap;
    ``time`` (T,) s."""
    ev, time = evaluation, np.asarray(time)
    variants = {"tracked": ev.tracked, "kinematic": ev.kinematic, "fem": ev.fem}
    plot_symmetry_cost(time, {v: m.cost for v, m in variants.items()}, folder / "symmetry")
    corners = {v: m.displacement[:, ev.mouth_corners] for v, m in variants.items()}
    plot_mouth_corners(time, corners, folder / "mouth_corners")
    if ev.lip_gap_truth is not None and ev.fidelity_fem and ev.fidelity_kinematic:
        fidelity = {"fem": ev.fidelity_fem, "kinematic": ev.fidelity_kinematic}
        peaks = {k: float(time[v]) for k, v in (ev.peak_frames or {}).items()}
        plot_fidelity(
            time, {m: f.overall for m, f in fidelity.items()},
            {m: f.regions for m, f in fidelity.items()}, list(ev.regions or []),
            folder / "fidelity", peaks=peaks,
        )  # fmt: skip
        gaps = {"truth": ev.lip_gap_truth, "fem": ev.lip_gap_fem, "kinematic": ev.lip_gap_kinematic}
        plot_lip_gap(time, gaps, folder / "lip_gap")
