"""Ground-truth facial performance of the demo: an expression field plus rigid head motion.

An *expression model* maps neutral actor-frame points (N, 3) m and a parameter vector
(P,) to displacements (N, 3) m. ``AnalyticFaceField`` is a documented smooth analytic
field; a CANDIDE-style action-unit model can replace it later by implementing the same
``ExpressionModel`` protocol (``param_names`` + ``displacement`` + ``to_dict``). More
fields (brows, lips, sideways jaw, cheeks, nose): ``physanim.capture.expressions``; the
performances of the library: ``physanim.capture.library``.

The field (all lengths m, angles rad):

* ``jaw_open`` in [0, 1]: points below the lip line rotate about a horizontal x-axis
  through ``jaw_pivot`` (the temporomandibular joints) by ``jaw_open * jaw_max_angle``
  (opening: chin moves down and back). The weight blends from 0 at ``lip_gap`` above
  the lip line (a straight line through the two mouth corners) to 1 at ``jaw_blend``
  below it with a C1 smoothstep, so the lips stretch smoothly.
* ``smile_L`` / ``smile_R`` in [0, 1]: the mouth corner on that side is pulled by
  ``smile_vector`` (x mirrored for the right side) with a Gaussian falloff of std
  ``smile_sigma`` around the neutral corner.

Head motion: ``x_world = R(rotvec) (x + d - head_center) + head_center + translation``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Protocol

import numpy as np
from scipy.spatial.transform import Rotation


class ExpressionModel(Protocol):
    """Maps neutral points (N, 3) m and parameters (P,) to displacements (N, 3) m; its
    ``to_dict`` is what the ground truth records of it (JSON-ready)."""

    param_names: tuple[str, ...]

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray: ...

    def to_dict(self) -> dict: ...


def smoothstep(x: np.ndarray) -> np.ndarray:
    """C1 smoothstep: 0 for x <= 0, 1 for x >= 1, 3x^2 - 2x^3 between."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


#: Jaw joint (temporomandibular) axis point of the actor, actor frame; m.
JAW_PIVOT: tuple[float, float, float] = (0.0, 0.005, -0.085)
#: The jaw weight is 0 this far above the lip line; m.
LIP_GAP = 0.001
#: ...and 1 this far below it; m.
JAW_BLEND = 0.007


def lip_line_y(points: np.ndarray, ch_left: np.ndarray, ch_right: np.ndarray) -> np.ndarray:
    """Height (N,) m of the lip line (the straight line through the mouth corners ``ch_left``,
    ``ch_right`` (3,) m) at the x of each of ``points`` (N, 3) m."""
    slope = (ch_left[1] - ch_right[1]) / (ch_left[0] - ch_right[0])
    return ch_right[1] + slope * (points[:, 0] - ch_right[0])


def jaw_weight(
    points: np.ndarray,
    ch_left: np.ndarray,
    ch_right: np.ndarray,
    lip_gap: float = LIP_GAP,
    jaw_blend: float = JAW_BLEND,
) -> np.ndarray:
    """How much (N,) of the jaw's motion each of ``points`` (N, 3) m follows: 0 from
    ``lip_gap`` m above the lip line up, 1 from ``jaw_blend`` m below it down, C1 between."""
    below = (lip_line_y(points, ch_left, ch_right) + lip_gap - points[:, 1]) / (lip_gap + jaw_blend)
    return smoothstep(below)


class JsonFields:
    """``to_dict`` for a frozen dataclass of floats and float tuples (an expression field)."""

    def to_dict(self) -> dict:
        """JSON-ready parameters (ground truth)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


@dataclass(frozen=True)
class AnalyticFaceField(JsonFields):
    """Jaw drop + per-side smile field; parameters documented in the module docstring."""

    ch_left: tuple[float, float, float]
    ch_right: tuple[float, float, float]
    jaw_pivot: tuple[float, float, float] = JAW_PIVOT
    jaw_max_angle: float = 0.2
    lip_gap: float = LIP_GAP
    jaw_blend: float = JAW_BLEND
    smile_sigma: float = 0.013
    smile_vector: tuple[float, float, float] = (0.004, 0.005, -0.002)
    param_names: tuple[str, ...] = field(default=("jaw_open", "smile_L", "smile_R"))

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) m of neutral ``points`` (N, 3) m for ``params`` (3,)."""
        jaw, smile_l, smile_r = (float(p) for p in params)
        cl, cr = np.asarray(self.ch_left), np.asarray(self.ch_right)
        w = jaw_weight(points, cl, cr, self.lip_gap, self.jaw_blend)
        pivot = np.asarray(self.jaw_pivot)
        rot = Rotation.from_rotvec([jaw * self.jaw_max_angle, 0.0, 0.0]).as_matrix()
        rel = points - pivot
        disp = w[:, None] * (rel @ rot.T - rel)
        sv = np.asarray(self.smile_vector)
        for amp, corner, sign in ((smile_l, cl, 1.0), (smile_r, cr, -1.0)):
            g = np.exp(-((points - corner) ** 2).sum(axis=1) / (2.0 * self.smile_sigma**2))
            disp += amp * g[:, None] * (sv * np.array([sign, 1.0, 1.0]))
        return disp


@dataclass(frozen=True)
class Performance:
    """Per-frame ground truth: ``times`` (T,) s, ``params`` (T, P), head ``rotvec`` (T, 3)
    rad and ``translation`` (T, 3) m about ``head_center`` (3,) m (actor frame)."""

    times: np.ndarray
    params: np.ndarray
    rotvec: np.ndarray
    translation: np.ndarray
    head_center: np.ndarray

    def head_pose(self) -> np.ndarray:
        """(T, 4, 4) rigid transforms world <- head-fixed actor frame."""
        rot = Rotation.from_rotvec(self.rotvec).as_matrix()
        pose = np.tile(np.eye(4), (len(self.times), 1, 1))
        pose[:, :3, :3] = rot
        pose[:, :3, 3] = self.head_center - rot @ self.head_center + self.translation
        return pose


def bump(s: np.ndarray, start: float, stop: float) -> np.ndarray:
    """Smooth pulse sin^2 over [start, stop] of normalised time ``s``, 0 elsewhere."""
    x = np.clip((s - start) / (stop - start), 0.0, 1.0)
    return np.sin(np.pi * x) ** 2


def demo_performance(n_frames: int, fps: float, seed: int) -> Performance:
    """The demo sequence: jaw drop, then an asymmetric smile (left stronger), back to neutral.

    Expression timing is fixed in normalised time s = i / (T - 1); the rigid head motion
    (``moving_head``) draws its phases from ``seed``.
    """
    s = np.linspace(0.0, 1.0, n_frames)
    params = np.stack(
        [bump(s, 0.03, 0.45), bump(s, 0.45, 0.97), 0.55 * bump(s, 0.52, 0.97)], axis=1
    )
    return moving_head(params, fps, np.random.default_rng(seed))


def moving_head(
    params: np.ndarray,
    fps: float,
    rng: np.random.Generator,
    *,
    head_rotation_amp_rad: float = 0.035,
    head_translation_amp_m: float = 0.003,
    head_center: tuple[float, float, float] = (0.0, 0.0, -0.09),
) -> Performance:
    """The performance of expression ``params`` (T, P) at ``fps`` frames/s with rigid head
    motion: rotation vectors and translations each a sum of slow sinusoids (0.4-1 cycles per
    sequence, phases drawn from ``rng``) of the given amplitudes, zero at frame 0."""
    n_frames = len(params)
    times = np.arange(n_frames) / fps
    s = np.linspace(0.0, 1.0, n_frames)
    phase = rng.uniform(0, 2 * np.pi, size=(2, 3))
    freq = rng.uniform(0.4, 1.0, size=(2, 3))  # cycles per sequence

    def wave(k: int) -> np.ndarray:
        arg = 2 * np.pi * freq[k] * s[:, None] + phase[k]
        return np.sin(arg) - np.sin(phase[k])

    return Performance(
        times=times,
        params=params,
        rotvec=head_rotation_amp_rad * wave(0),
        translation=head_translation_amp_m * wave(1),
        head_center=np.asarray(head_center, dtype=np.float64),
    )
