"""Colours of the face renders: skin and background, scalar colour maps and their bar."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import Normalize
from matplotlib.figure import Figure as MplFigure

#: default skin albedo, sRGB 0-1
SKIN = (0.89, 0.72, 0.62)
BACKGROUND = (1.0, 1.0, 1.0)
#: colour of a scalar that has no value (NaN: e.g. an error where there is no truth), sRGB 0-1
NO_VALUE = (0.6, 0.6, 0.6)
#: height of the colour-bar strip under the view, pixels
BAR_HEIGHT = 64


@dataclass(frozen=True)
class ColourMap:
    """How scalars become colours: matplotlib ``cmap`` name over ``clim`` (lo, hi) in the
    scalars' unit, bar titled ``label`` (e.g. "displacement (mm)", "von Mises stress (kPa)";
    the default map starts light so that shading stays visible at zero).  With
    ``categories`` the scalars are integer labels 0..len-1 (e.g. tissue regions) drawn with
    a qualitative map and a legend of the category names."""

    label: str
    clim: tuple[float, float] = (0.0, 1.0)
    cmap: str = "YlOrRd"
    categories: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if self.categories is None and not self.clim[1] > self.clim[0]:
            raise ValueError(f"ColourMap {self.label!r}: clim must be (lo, hi) with hi > lo")
        if self.cmap not in colormaps:
            raise ValueError(f"ColourMap {self.label!r}: unknown matplotlib cmap {self.cmap!r}")

    @classmethod
    def spanning(cls, scalars: np.ndarray, label: str = "") -> ColourMap:
        """A map over the range of ``scalars`` (widened to 1 unit if they are constant)."""
        lo, hi = float(np.min(scalars)), float(np.max(scalars))
        return cls(label=label, clim=(lo, hi if hi > lo else lo + 1.0))

    def colours(self, scalars: np.ndarray) -> np.ndarray:
        """(K,) scalars -> (K, 3) uint8 sRGB; NaN -> ``NO_VALUE``."""
        if self.categories is not None:
            table = category_colours(len(self.categories))
            idx = np.clip(np.asarray(scalars).astype(np.int64), 0, len(self.categories) - 1)
            rgb = table[idx]
        else:
            lo, hi = self.clim
            rgb = colormaps[self.cmap](Normalize(lo, hi, clip=True)(scalars))[:, :3]
            rgb[~np.isfinite(scalars)] = NO_VALUE
        return np.round(255 * rgb).astype(np.uint8)


def category_colours(n: int) -> np.ndarray:
    """(n, 3) float distinct colours (tab10, then tab20)."""
    base = colormaps["tab10" if n <= 10 else "tab20"]
    return np.array([base(i % base.N)[:3] for i in range(n)])


def colour_bar(colour_map: ColourMap, width: int, height: int = BAR_HEIGHT) -> np.ndarray:
    """(height, width, 3) uint8 strip: a horizontal labelled colour bar, or a legend of the
    categories (matplotlib, Agg)."""
    dpi = 100
    fig = MplFigure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor=BACKGROUND)
    if colour_map.categories is None:
        ax = fig.add_axes((0.08, 0.62, 0.84, 0.26))
        lo, hi = colour_map.clim
        ramp = np.linspace(lo, hi, 256)[None, :]
        ax.imshow(ramp, aspect="auto", cmap=colour_map.cmap, extent=(lo, hi, 0, 1))
        ax.set_yticks([])
        ax.tick_params(labelsize=8, length=3, pad=1)
        ax.set_xlabel(colour_map.label, fontsize=9, labelpad=1)
    else:
        from matplotlib.patches import Patch

        colours = category_colours(len(colour_map.categories))
        handles = [
            Patch(fc=c, ec="0.3", label=n)
            for c, n in zip(colours, colour_map.categories, strict=True)
        ]
        fig.legend(
            handles=handles,
            loc="center",
            ncol=-(-len(handles) // -(-len(handles) // max(1, width // 90))),  # balanced rows
            fontsize=8,
            frameon=False,
            title=colour_map.label,
            title_fontsize=9,
            handlelength=1.2,
            columnspacing=0.8,
        )
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
