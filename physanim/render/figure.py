"""Renders of capsule figures: PNG frames (matplotlib, Agg), an MP4 (OpenCV) and a plot
of joint angles.  Orthographic view from a camera at azimuth/elevation (deg) about +y."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import cv2
import numpy as np
from matplotlib.figure import Figure as MplFigure
from matplotlib.patches import Polygon

from physanim.dynamics.contact import Environment
from physanim.dynamics.figure import Figure
from physanim.dynamics.kinematics import capsule_segments, forward_kinematics


def view_basis(azimuth: float, elevation: float) -> np.ndarray:
    """Rows: screen right, screen up, depth towards the camera (3, 3), world y up."""
    az, el = np.radians(azimuth), np.radians(elevation)
    toward = np.array([np.cos(el) * np.sin(az), np.sin(el), np.cos(el) * np.cos(az)])
    right = np.cross([0.0, 1.0, 0.0], toward)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(toward, right), toward])


def stadium(a: np.ndarray, b: np.ndarray, r: float, n: int = 12) -> np.ndarray:
    """Outline (2n, 2) of the 2-D capsule with axis a-b (2,) and radius r."""
    d = b - a
    ang = np.arctan2(d[1], d[0]) if np.hypot(*d) > 1e-12 else 0.0
    t = np.linspace(-np.pi / 2, np.pi / 2, n)
    cap_b = b + r * np.stack([np.cos(ang + t), np.sin(ang + t)], axis=1)
    cap_a = a + r * np.stack([np.cos(ang + np.pi + t), np.sin(ang + np.pi + t)], axis=1)
    return np.concatenate([cap_b, cap_a])


def _box_faces(lo: np.ndarray, hi: np.ndarray) -> list[np.ndarray]:
    c = np.array(
        [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    )
    quads = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]
    return [c[list(f)] for f in quads]


def _link_color(name: str) -> str:
    return "#c0392b" if name.startswith("r_") else "#2e6fba" if name.startswith("l_") else "#7f8c8d"


def render_frames(
    fig: Figure,
    q: np.ndarray,
    base_pos: np.ndarray,
    out_dir: str | Path,
    *,
    env: Environment | None = None,
    trails: Mapping[str, np.ndarray] | None = None,
    guides: Mapping[str, np.ndarray] | None = None,
    azimuth: float = 60.0,
    elevation: float = 15.0,
    size_px: tuple[int, int] = (640, 480),
    title: str = "",
    progress: Callable[[int, int], None] | None = None,
) -> list[Path]:
    """Draw every frame to ``out_dir/frame_0000.png``...; returns the paths.

    q (F, n) rad; base_pos (F, 3) m; ``trails`` maps a label to a point path (F, 3) m
    drawn up to the current frame (e.g. a hand tip or the centre of mass); ``guides`` maps
    a label to a polyline (k, 3) m drawn whole, dashed, in every frame (e.g. a root path).
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    basis = view_basis(azimuth, elevation)
    kin = forward_kinematics(fig, q, base_pos=np.asarray(base_pos, float))
    seg_a, seg_b = capsule_segments(fig, kin)
    solid = np.flatnonzero(fig.radius > 0)
    guide_pts = [np.asarray(g, float) for g in (guides or {}).values()]
    pts = np.concatenate([seg_a.reshape(-1, 3), seg_b.reshape(-1, 3), *guide_pts]) @ basis.T
    pad = 0.4
    xlim = (pts[:, 0].min() - pad, pts[:, 0].max() + pad)
    ylim = (min(pts[:, 1].min(), 0.0) - pad, pts[:, 1].max() + pad)
    env_faces: list[np.ndarray] = []
    if env is not None:
        world = np.concatenate([seg_a.reshape(-1, 3), seg_b.reshape(-1, 3)])
        (x0, _, z0), (x1, _, z1) = world.min(axis=0) - 0.5, world.max(axis=0) + 0.5
        h = env.ground_height
        env_faces.append(np.array([[x0, h, z0], [x1, h, z0], [x1, h, z1], [x0, h, z1]]))
        for lo, hi in env.boxes:
            env_faces.extend(_box_faces(np.asarray(lo, float), np.asarray(hi, float)))
    colors = [_link_color(fig.joint_names[i]) for i in solid]
    dpi = 100
    paths = []
    for f in range(len(q)):
        fg = MplFigure(figsize=(size_px[0] / dpi, size_px[1] / dpi), dpi=dpi)
        ax = fg.subplots()
        ax.set_xlim(*xlim)
        ax.set_ylim(*ylim)
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(f"{title} frame {f}", fontsize=9)
        for k, face in enumerate(env_faces):
            p2 = face @ basis[:2].T
            shade = "#d9d2c5" if k == 0 else "#a6937c"
            ax.add_patch(Polygon(p2, closed=True, fc=shade, ec="#6b5b45", lw=0.5, zorder=0))
        a2 = seg_a[f, solid] @ basis.T
        b2 = seg_b[f, solid] @ basis.T
        order = np.argsort(0.5 * (a2[:, 2] + b2[:, 2]))  # far to near
        for z, i in enumerate(order):
            outline = stadium(a2[i, :2], b2[i, :2], fig.radius[solid[i]])
            ax.add_patch(Polygon(outline, closed=True, fc=colors[i], ec="k", lw=0.6, zorder=2 + z))
        for label, line in (guides or {}).items():
            p2 = np.asarray(line) @ basis[:2].T
            ax.plot(p2[:, 0], p2[:, 1], "--", lw=1, color="0.35", label=label, zorder=1)
        for k, (label, path) in enumerate((trails or {}).items()):
            p2 = np.asarray(path)[: f + 1] @ basis[:2].T
            ax.plot(
                p2[:, 0], p2[:, 1], "-o", ms=2, lw=1, color=f"C{k + 2}", label=label, zorder=100
            )
        if trails or guides:
            ax.legend(loc="upper right", fontsize=7)
        path = out_dir / f"frame_{f:04d}.png"
        fg.savefig(path, dpi=dpi)
        paths.append(path)
        if progress is not None:
            progress(f + 1, len(q))
    return paths


def write_video(frames: Sequence[str | Path], path: str | Path, fps: float) -> Path:
    """Encode PNG frames into an MP4 (OpenCV, codec mp4v) at ``fps`` frames/s."""
    path = Path(path)
    if not frames:
        raise ValueError("write_video: no frames given")
    first = cv2.imread(str(frames[0]))
    if first is None:
        raise FileNotFoundError(f"cannot read frame image {frames[0]}")
    h, w = first.shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
    if not writer.isOpened():
        raise RuntimeError(f"OpenCV cannot open {path} for writing with codec mp4v")
    for fr in frames:
        img = cv2.imread(str(fr))
        writer.write(img if img.shape[:2] == (h, w) else cv2.resize(img, (w, h)))
    writer.release()
    return path


def plot_joint_angles(
    times: np.ndarray,
    q: np.ndarray,
    names: Sequence[str],
    path: str | Path,
    *,
    joints: Sequence[str] | None = None,
    simulated: np.ndarray | None = None,
    key_times: Sequence[float] = (),
    title: str = "",
) -> Path:
    """Plot joint angles (deg) over time (s); simulated stretches (F, n) drawn bold,
    key times as vertical lines.  ``joints`` selects the curves (default: those that move)."""
    names = list(names)
    sel = (
        [names.index(j) for j in joints]
        if joints
        else list(np.flatnonzero(np.ptp(q, axis=0) > 1e-9))
    )
    fg = MplFigure(figsize=(9, 5), dpi=100)
    ax = fg.subplots()
    for k, i in enumerate(sel):
        deg = np.degrees(q[:, i])
        ax.plot(times, deg, lw=1, color=f"C{k % 10}", label=names[i])
        if simulated is not None and simulated[:, i].any():
            ax.plot(times, np.where(simulated[:, i], deg, np.nan), lw=3, color=f"C{k % 10}")
    for t in key_times:
        ax.axvline(t, color="k", lw=0.5, ls="--")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("joint angle (deg)")
    ax.set_title(f"{title + ': ' if title else ''}joint angles (bold: simulated; dashed: keys)")
    ax.legend(fontsize=6, ncol=3, loc="best")
    ax.grid(alpha=0.3)
    fg.tight_layout()
    fg.savefig(path)
    return Path(path)


def render_animation(
    fig: Figure,
    q: np.ndarray,
    base_pos: np.ndarray,
    fps: float,
    out_dir: str | Path,
    *,
    env: Environment | None = None,
    trail_links: Sequence[str] = (),
    com: np.ndarray | None = None,
    guides: Mapping[str, np.ndarray] | None = None,
    simulated: np.ndarray | None = None,
    key_times: Sequence[float] = (),
    title: str = "",
    azimuth: float = 60.0,
    elevation: float = 15.0,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, Path]:
    """PNG frames (``out_dir/frames/``), ``animation.mp4`` and ``joint_angles.png``.

    q (F, n) rad and base_pos (F, 3) m at ``fps``; trails of the distal ends of
    ``trail_links`` and of ``com`` (F, 3) m if given; ``guides`` as in :func:`render_frames`.
    Returns the written paths.
    """
    out_dir = Path(out_dir)
    kin = forward_kinematics(fig, q, base_pos=np.asarray(base_pos, float))
    _, tips = capsule_segments(fig, kin)
    trails = {f"{name} tip": tips[:, fig.index(name)] for name in trail_links}
    if com is not None:
        trails["COM"] = np.asarray(com)
    frames = render_frames(
        fig,
        q,
        base_pos,
        out_dir / "frames",
        env=env,
        trails=trails,
        guides=guides,
        azimuth=azimuth,
        elevation=elevation,
        title=title,
        progress=progress,
    )
    times = np.arange(len(q)) / fps
    return {
        "frames": out_dir / "frames",
        "video": write_video(frames, out_dir / "animation.mp4", fps),
        "plot": plot_joint_angles(
            times,
            q,
            fig.joint_names,
            out_dir / "joint_angles.png",
            simulated=simulated,
            key_times=key_times,
            title=title,
        ),
    }
