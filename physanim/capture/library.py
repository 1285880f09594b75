"""A named library of facial performances of the virtual actor, for tests and benchmarks.

Each performance is a sequence of *beats*: a beat is one or more expressions
(``physanim.capture.expressions``) rising and falling together as one sin^2 bump over an
equal share of the sequence (from s = 0.03 to 0.97 of normalised time), neutral at both
ends; every expression is in exactly one beat, so it peaks once
(``physanim.evaluate.truth.Truth.peak_frames`` finds it). The rigid head motion is the demo's
(``moving_head``), its phases drawn from the seed and the performance's name. ``demo`` is
the demo's own performance (jaw drop, asymmetric smile) with the demo's field.

The library is split into :data:`TUNING` (for tuning loops) and :data:`HELD_OUT` (left out
of them, to check what was tuned); :data:`PERFORMANCE_NAMES` holds both.

Datasets: ``<performance>-s<seed>[-coarse][-markerless]`` (:func:`dataset_name`), full
(:data:`FULL_FRAMES` frames) or coarse (:data:`COARSE_FRAMES`), with or without painted
markers; the pipeline generates a missing one on demand from its name (``--dataset
data/library/lips-s1-coarse``; ``tasks.ingest.ensure_demo``). Generate them in bulk with
``python -m physanim.capture.make_library`` (``physanim.capture.make_library``).
"""

from __future__ import annotations

import re
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from physanim.capture.expressions import face_field
from physanim.capture.performance import (
    AnalyticFaceField,
    ExpressionModel,
    Performance,
    bump,
    demo_performance,
    moving_head,
)

if TYPE_CHECKING:
    from physanim.capture.params import DemoParams  # whose validator imports this module

#: The demo's own performance (``demo_performance`` with ``AnalyticFaceField``).
DEMO = "demo"
#: Frames of a full dataset (3 s at 30 fps, like the demo) and of a coarse one (tests).
FULL_FRAMES = 90
COARSE_FRAMES = 24
#: Seeds ``python -m physanim.capture.make_library`` generates by default.
DEFAULT_SEEDS = (0, 1, 2)


@dataclass(frozen=True)
class PerformanceSpec:
    """A library performance: ``beats``, each expression name -> peak value in (0, 1],
    performed one after another; ``description`` says what the actor does."""

    description: str
    beats: tuple[Mapping[str, float], ...]

    def __post_init__(self) -> None:
        names = [n for beat in self.beats for n in beat]
        if len(set(names)) != len(names):
            raise ValueError(f"{self.description}: an expression is in several beats")
        if not all(0.0 < v <= 1.0 for beat in self.beats for v in beat.values()):
            raise ValueError(f"{self.description}: peak values must be in (0, 1]")

    @property
    def names(self) -> tuple[str, ...]:
        """Expression names in order of their beats."""
        return tuple(n for beat in self.beats for n in beat)

    def expression(self, n_frames: int) -> np.ndarray:
        """Parameters (T, P) per frame, columns in the order of ``names``."""
        s = np.linspace(0.0, 1.0, n_frames)
        edges = np.linspace(0.03, 0.97, len(self.beats) + 1)
        columns = [
            value * bump(s, edges[k], edges[k + 1])
            for k, beat in enumerate(self.beats)
            for value in beat.values()
        ]
        return np.stack(columns, axis=1)


#: The library, tuning part first. One-sided smile: ``smile_L`` or ``smile_R`` alone.
LIBRARY: dict[str, PerformanceSpec] = {
    "brows": PerformanceSpec("brow raise, then frown", ({"brow_raise": 1.0}, {"frown": 1.0})),
    "lips": PerformanceSpec(
        "lip pucker, funnel, press",
        ({"lip_pucker": 1.0}, {"lip_funnel": 1.0}, {"lip_press": 1.0}),
    ),
    "jaw_side": PerformanceSpec(
        "jaw to the left, to the right, then open",
        ({"jaw_left": 1.0}, {"jaw_right": 1.0}, {"jaw_open": 0.7}),
    ),
    "cheeks": PerformanceSpec(
        "cheek puff, nose wrinkle, one-sided smile (left)",
        ({"cheek_puff": 1.0}, {"nose_wrinkle": 1.0}, {"smile_L": 1.0}),
    ),
    "vowels": PerformanceSpec(
        "speech-like: 'o' (jaw + funnel), 'u' (pucker), 'i' (smile), 'm' (press)",
        (
            {"jaw_open": 0.5, "lip_funnel": 0.6},
            {"lip_pucker": 0.8},
            {"smile_L": 0.6, "smile_R": 0.6},
            {"lip_press": 0.8},
        ),
    ),
    "emotions": PerformanceSpec(
        "surprise (brows + jaw), anger (frown + press), disgust (nose wrinkle + right smile)",
        (
            {"brow_raise": 0.8, "jaw_open": 0.4},
            {"frown": 1.0, "lip_press": 0.7},
            {"nose_wrinkle": 0.9, "smile_R": 0.4},
        ),
    ),
    "medley": PerformanceSpec(
        "one-sided smile (right), jaw to the left, cheek puff, brow raise with pucker",
        (
            {"smile_R": 1.0},
            {"jaw_left": 0.8},
            {"cheek_puff": 0.8},
            {"brow_raise": 0.6, "lip_pucker": 0.5},
        ),
    ),
}
#: Performances for tuning loops, and those left out of them (combinations of the tuning
#: part's expressions, in new timings and mixtures).
TUNING: tuple[str, ...] = (DEMO, "brows", "lips", "jaw_side", "cheeks")
HELD_OUT: tuple[str, ...] = ("vowels", "emotions", "medley")
#: Every performance ``DemoParams.performance`` accepts.
PERFORMANCE_NAMES: tuple[str, ...] = (*TUNING, *HELD_OUT)


def check_performance(name: str) -> str:
    """``name`` if the library has it; ValueError listing the library's names otherwise."""
    if name not in PERFORMANCE_NAMES:
        raise ValueError(
            f"unknown performance {name!r}; the library has: {', '.join(PERFORMANCE_NAMES)}"
        )
    return name


def performance_setup(
    name: str, markers: Mapping[str, np.ndarray], n_frames: int, fps: float, seed: int
) -> tuple[ExpressionModel, Performance]:
    """The expression field (placed from the neutral markers, name -> (3,) m) and the
    per-frame truth of performance ``name``: ``demo`` is ``demo_performance`` with
    ``AnalyticFaceField``; a library performance drives ``face_field`` with its own
    expressions, head motion drawn from ``[seed, crc32(name)]``."""
    if check_performance(name) == DEMO:
        field = AnalyticFaceField(ch_left=tuple(markers["ch_L"]), ch_right=tuple(markers["ch_R"]))
        return field, demo_performance(n_frames, fps, seed)
    spec = LIBRARY[name]
    rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
    return face_field(markers).select(spec.names), moving_head(spec.expression(n_frames), fps, rng)


_NAME = re.compile(
    r"(?P<performance>\w+?)-s(?P<seed>\d+)(?P<coarse>-coarse)?(?P<bare>-markerless)?"
)


def dataset_name(performance: str, seed: int, *, coarse: bool = False, markers: bool = True) -> str:
    """Folder name of a library dataset, e.g. ``lips-s1-coarse``."""
    return (
        f"{check_performance(performance)}-s{seed}"
        + ("-coarse" if coarse else "")
        + ("" if markers else "-markerless")
    )


def library_params(name: str, base: DemoParams) -> DemoParams | None:
    """The demo parameters that generate dataset ``name``: ``base`` for ``demo``; for a
    library dataset (``dataset_name``'s form), ``base``'s with the performance, seed, frame
    count and markers the name gives; None for any other name."""
    if name == DEMO:
        return base
    match = _NAME.fullmatch(name)
    if match is None or match["performance"] not in PERFORMANCE_NAMES:
        return None
    update = {
        "performance": match["performance"],
        "seed": int(match["seed"]),
        "n_frames": COARSE_FRAMES if match["coarse"] else FULL_FRAMES,
        "markers": match["bare"] is None,
    }
    return base.model_copy(update=update)
