"""Checks of what a saved plot shows, rather than of its file size.

``capture_figures`` records every matplotlib figure as it is saved, so a test can map its own
ground-truth data through the axes' data-to-pixel transform and look in the PNG for the line's
colour there (``curve_drawn``).  Figures must be saved without ``bbox_inches="tight"`` (the
mapping is then a pure scaling by the save dpi).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from matplotlib.colors import to_rgb
from matplotlib.figure import Figure


def capture_figures(monkeypatch) -> list[tuple[Figure, Path]]:
    """Patch ``Figure.savefig``; the returned list fills with (figure, path) as plots are saved."""
    saved: list[tuple[Figure, Path]] = []
    real = Figure.savefig

    def savefig(fig, fname, *args, **kwargs):
        out = real(fig, fname, *args, **kwargs)
        saved.append((fig, Path(fname)))
        return out

    monkeypatch.setattr(Figure, "savefig", savefig)
    return saved


def read_rgb(path: str | Path) -> np.ndarray:
    """The PNG as (H, W, 3) uint8 RGB; fails if it cannot be decoded."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert img is not None, f"{path} is not a readable image"
    return img[..., ::-1]


def assert_not_blank(img: np.ndarray, min_ink: float = 0.01) -> None:
    """At least ``min_ink`` of the pixels differ from the most common (background) colour."""
    flat = img.reshape(-1, 3)
    colours, counts = np.unique(flat, axis=0, return_counts=True)
    background = colours[np.argmax(counts)]
    ink = np.any(np.abs(flat.astype(int) - background) > 40, axis=1).mean()
    assert ink >= min_ink, f"only {ink:.2%} of the pixels differ from the background"


def colour_pixels(img: np.ndarray, colour, tol: float = 60.0) -> np.ndarray:
    """Boolean (H, W) mask of pixels within ``tol`` (RGB, 0-255) of a matplotlib colour."""
    rgb = 255.0 * np.array(to_rgb(colour))
    return np.linalg.norm(img.astype(float) - rgb, axis=-1) < tol


def to_pixels(img, fig, ax, x, y) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) in the PNG of the data points (x, y) of ``ax``, by its data transform."""
    scale = img.shape[1] / fig.bbox.width
    disp = ax.transData.transform(np.column_stack([x, y]))
    return np.rint(img.shape[0] - disp[:, 1] * scale).astype(int), np.rint(
        disp[:, 0] * scale
    ).astype(int)


def curve_drawn(img, fig, ax, x, y, colour, radius_px=2, tol=60.0, covered=None) -> float:
    """Fraction of the points (x, y) (data units of ``ax``) near which ``colour`` is drawn.

    Each point goes through the axes' data-to-display transform, scaled to the PNG's size;
    a point counts when a pixel of that colour lies within ``radius_px`` of it.  ``covered``
    (boolean, per point) leaves out points that a line drawn later hides; 1.0 when all are.
    """
    mask = colour_pixels(img, colour, tol)
    rows, cols = to_pixels(img, fig, ax, x, y)
    keep = np.ones(len(rows), bool) if covered is None else ~np.asarray(covered)
    r_ = radius_px
    hits = [
        mask[max(r - r_, 0) : r + r_ + 1, max(c - r_, 0) : c + r_ + 1].any()
        for r, c in zip(rows[keep], cols[keep], strict=True)
    ]
    return float(np.mean(hits)) if hits else 1.0
