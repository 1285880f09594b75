"""Renders of the muscle-driven arm (seed 000): frames and an MP4 of bones and spindle muscles
coloured by activation, time plots per muscle (seed figures 5.6-5.13) and the model's curves.

Matplotlib with the Agg canvas (headless); the arm moves in the x-y plane, seen from +z.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import ListedColormap, Normalize
from matplotlib.figure import Figure as MplFigure
from matplotlib.patches import Circle, Polygon

from physanim.muscle import curves
from physanim.muscle.arm import ArmResult
from physanim.muscle.params import ArmParams, ShapeParams
from physanim.muscle.shape import activation_colour, spindle_semi_axes, spindle_volume
from physanim.render.figure import stadium, write_video

BONE_RADIUS = 0.01  # m, drawn bone thickness (the links' cylinders would hide the muscles)
#: the belly colours (1, 1 - a, 1 - a) as a colour map over activation 0..1
ACTIVATION_CMAP = ListedColormap(activation_colour(np.linspace(0.0, 1.0, 256)), "activation")


def _ellipse(centre: np.ndarray, axis: np.ndarray, long: float, short: float, n: int = 40):
    """Outline (n, 2) of the ellipse with semi-axes long (along unit ``axis``) and short."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    normal = np.array([-axis[1], axis[0]])
    return centre + long * np.cos(t)[:, None] * axis + short * np.sin(t)[:, None] * normal


def _nearest_on_segments(point: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Closest point (2,) to ``point`` on the polyline through ``joints`` (k, 2)."""
    a, b = joints[:-1], joints[1:]
    ab = b - a
    s = np.clip(np.einsum("ki,ki->k", point - a, ab) / np.einsum("ki,ki->k", ab, ab), 0, 1)
    near = a + s[:, None] * ab
    return near[np.argmin(np.linalg.norm(near - point, axis=1))]


def render_arm_frames(
    result: ArmResult,
    arm: ArmParams,
    shape: ShapeParams,
    out_dir: str | Path,
    *,
    every: int = 1,
    size_px: int = 480,
    title: str = "",
    progress: Callable[[int, int], None] | None = None,
) -> list[Path]:
    """PNG frames ``frame_####.png`` of every ``every``-th sample: spindle bellies (side view
    of the volume-preserving ellipsoid) coloured (1, 1-a, 1-a), drawn behind the bones and
    numbered beside them (the names in a key below), tendons as lines, and a colour bar of
    activation."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    f0 = np.array([m.max_isometric_force for m in arm.muscles])
    l0 = np.array([m.optimal_fibre_length for m in arm.muscles])
    volume = spindle_volume(f0, l0, shape.specific_tension)
    long, short = spindle_semi_axes(result.fibre_length, volume)
    colours = activation_colour(result.activation)
    pts = np.concatenate([result.bodies.reshape(-1, 2), result.origin.reshape(-1, 2)])
    lo, hi = pts.min(0) - 0.06, pts.max(0) + 0.06
    frames = list(range(0, len(result.time), every))
    fig = MplFigure(figsize=(size_px / 100, size_px / 100), dpi=100)
    font = max(5.0, size_px / 70)
    names = [f"{k + 1} {m.name.replace('_', ' ')}" for k, m in enumerate(arm.muscles)]
    key = "\n".join("    ".join(names[i : i + 2]) for i in range(0, len(names), 2))
    key_height = (1.75 * font * ((len(names) + 1) // 2) + 8) / size_px  # pt -> px at 100 dpi
    paths = []
    for done, f in enumerate(frames, start=1):
        fig.clear()
        fig.text(0.02, 0.01, key, fontsize=font, va="bottom", ha="left", color="0.15")
        ax = fig.add_axes((0.0, key_height, 0.84, 0.92 - key_height))
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.axis("off")
        shoulder = np.array([[0.0, lo[1] + 0.02], [0.0, hi[1] - 0.02]])
        ax.plot(shoulder[:, 0], shoulder[:, 1], color="0.6", lw=6, solid_capstyle="round")
        joints = result.bodies[f, 1:]
        for k in range(len(arm.muscles)):
            o, i = result.origin[f, k], result.insertion[f, k]
            axis = (o - i) / np.linalg.norm(o - i)
            centre = 0.5 * (o + i)
            ends = centre + np.array([1.0, -1.0])[:, None] * long[f, k] * axis
            ax.plot([o[0], ends[0, 0]], [o[1], ends[0, 1]], color="0.25", lw=1.2, zorder=3)
            ax.plot([i[0], ends[1, 0]], [i[1], ends[1, 1]], color="0.25", lw=1.2, zorder=3)
            outline = _ellipse(centre, axis, long[f, k], short[f, k])
            ax.add_patch(Polygon(outline, fc=colours[f, k], ec="0.2", lw=0.8, zorder=2))
            away = centre - _nearest_on_segments(centre, joints)  # badge on the far side
            normal = np.array([-axis[1], axis[0]])
            side = 1.0 if normal @ away >= 0 else -1.0
            ax.text(
                *(centre + side * (short[f, k] + 0.014) * normal),
                str(k + 1),
                fontsize=font,
                ha="center",
                va="center",
                zorder=7,
                bbox={"boxstyle": "circle,pad=0.15", "fc": "white", "ec": "0.4", "lw": 0.6},
            )
        for a, b in zip(joints[:-1], joints[1:], strict=True):
            ax.add_patch(Polygon(stadium(a, b, BONE_RADIUS), fc="0.85", ec="0.3", lw=1, zorder=4))
        if arm.load_mass > 0:
            ax.add_patch(Circle(joints[-1], 0.025, fc="0.35", ec="k", zorder=5))
        ax.plot(joints[:-1, 0], joints[:-1, 1], "ko", ms=4, zorder=6)
        cax = fig.add_axes((0.86, 0.12, 0.035, 0.7))
        bar = fig.colorbar(ScalarMappable(Normalize(0.0, 1.0), ACTIVATION_CMAP), cax=cax)
        bar.set_label("activation (0-1)", fontsize=font)
        bar.ax.tick_params(labelsize=font)
        fig.suptitle(f"{title}  t = {1000 * result.time[f]:.0f} ms", fontsize=10)
        path = out_dir / f"frame_{done - 1:04d}.png"
        fig.savefig(path, dpi=100)
        paths.append(path)
        if progress is not None:
            progress(done, len(frames))
    return paths


def render_arm_video(
    result: ArmResult,
    arm: ArmParams,
    shape: ShapeParams,
    out_dir: str | Path,
    *,
    fps: float = 25.0,
    size_px: int = 480,
    title: str = "",
    progress: Callable[[int, int], None] | None = None,
) -> Path:
    """Frames at ``fps`` (sub-sampled from the result) and ``arm.mp4`` in ``out_dir``."""
    dt = float(result.time[1] - result.time[0])
    every = max(1, int(round(1.0 / (fps * dt))))
    frames = render_arm_frames(
        result, arm, shape, out_dir, every=every, size_px=size_px, title=title, progress=progress
    )
    return write_video(frames, Path(out_dir) / "arm.mp4", 1.0 / (every * dt))


def plot_muscle_timeseries(
    results: Mapping[str, ArmResult],
    arm: ArmParams,
    path: str | Path,
    quantity: str = "activation",
) -> Path:
    """One panel per muscle, one line per condition, over 0-1000 ms (seed figures 5.6-5.13).

    ``quantity``: "activation" (0-1) or "fibre_length" (normalised, l^M / l0).
    """
    if quantity not in ("activation", "fibre_length"):
        raise ValueError(f"quantity must be 'activation' or 'fibre_length', got {quantity!r}")
    l0 = np.array([m.optimal_fibre_length for m in arm.muscles])
    n = len(arm.muscles)
    cols = 2
    rows = (n + cols - 1) // cols
    fig = MplFigure(figsize=(5 * cols, 3 * rows), dpi=100)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for k, muscle in enumerate(arm.muscles):
        ax = axes[k]
        for label, res in results.items():
            y = res.activation[:, k] if quantity == "activation" else res.fibre_length[:, k] / l0[k]
            ax.plot(1000 * res.time, y, label=label)
        what = "activation" if quantity == "activation" else "fibre length"
        ax.set_title(f"{muscle.name}: {what}")
        ax.set_xlabel("time (ms)")
        ax.set_ylabel("activation (0-1)" if quantity == "activation" else "l^M / l0 (unitless)")
        if quantity == "activation":
            ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    for ax in axes[n:]:
        ax.axis("off")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    return path


def plot_muscle_curves(path: str | Path) -> Path:
    """The normalised Zajac curves: force-length (active, passive), force-velocity, tendon."""
    fig = MplFigure(figsize=(12, 3.6), dpi=100)
    ax1, ax2, ax3 = fig.subplots(1, 3)
    length = np.linspace(0.3, 1.7, 300)
    ax1.plot(length, curves.active_force_length(length), label="active (a = 1)")
    ax1.plot(length, curves.passive_force_length(length), label="passive")
    ax1.set_ylim(0, 1.6)
    ax1.set_xlabel("fibre length l^M / l0 (unitless)")
    ax1.set_ylabel("fibre force / F0 (unitless)")
    ax1.set_title("force-length")
    velocity = np.linspace(-1.2, 1.0, 300)
    ax2.plot(velocity, curves.force_velocity(velocity))
    ax2.set_xlabel("fibre velocity / v_max (unitless, shortening < 0)")
    ax2.set_ylabel("force / isometric force (unitless)")
    ax2.set_title("force-velocity")
    strain = np.linspace(-0.01, 0.1, 300)
    ax3.plot(strain, curves.tendon_force(strain))
    ax3.axvline(curves.TENDON_TOE_STRAIN, color="0.6", ls="--", lw=0.8, label="end of toe region")
    ax3.set_xlabel("tendon strain (unitless)")
    ax3.set_ylabel("tendon force / F0 (unitless)")
    ax3.set_title("tendon force-strain")
    for ax in (ax1, ax2, ax3):
        ax.grid(alpha=0.3)
    ax1.legend(fontsize=8)
    ax3.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    return path


def plot_condition_summary(
    results: Mapping[str, ArmResult], joint_names: Sequence[str], path: str | Path
) -> Path:
    """Joint angles (deg), inverse-dynamics torques (N m) and the torque the muscles cannot
    produce (N m, the stretches where it is non-zero shaded) per condition and joint."""
    fig = MplFigure(figsize=(14, 4.0), dpi=100)
    axes = fig.subplots(1, 3)
    for c, (label, res) in enumerate(results.items()):
        ms = 1000 * res.time
        for j, name in enumerate(joint_names):
            kw = {"color": f"C{c}", "ls": "-" if j == 0 else "--", "label": f"{label} {name}"}
            axes[0].plot(ms, np.degrees(res.q[:, j]), **kw)
            axes[1].plot(ms, res.torque[:, j], **kw)
            missing = res.torque_residual[:, j]
            axes[2].plot(ms, missing, **kw)
            axes[2].fill_between(
                ms, 0.0, missing, where=np.abs(missing) > 1e-6, color=f"C{c}", alpha=0.2, lw=0
            )
    titles = ("joint angles", "inverse-dynamics torque", "missing torque (muscles too weak)")
    ylabels = ("angle (deg)", "torque (N m)", "required - produced torque (N m)")
    for ax, title, ylabel in zip(axes, titles, ylabels, strict=True):
        ax.set_title(title)
        ax.set_xlabel("time (ms)")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    return path
