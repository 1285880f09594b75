"""Ground-truth facial performance of the demo: an expression field plus rigid head motion.

An *expression model* maps neutral actor-frame points (N, 3) m and a parameter vector
(P,) to displacements (N, 3) m. ``AnalyticFaceField`` is a documented smooth analytic
field; a CANDIDE-style action-unit model can replace it later by implementing the same
``ExpressionModel`` protocol (``param_names`` + ``displacement``).

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
    """Maps neutral points (N, 3) m and parameters (P,) to displacements (N, 3) m."""

    param_names: tuple[str, ...]

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray: ...


def smoothstep(x: np.ndarray) -> np.ndarray:
    """C1 smoothstep: 0 for x <= 0, 1 for x >= 1, 3x^2 - 2x^3 between."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class AnalyticFaceField:
    """Jaw drop + per-side smile field; parameters documented in the module docstring."""

    ch_left: tuple[float, float, float]
    ch_right: tuple[float, float, float]
    jaw_pivot: tuple[float, float, float] = (0.0, 0.005, -0.085)
    jaw_max_angle: float = 0.2
    lip_gap: float = 0.001
    jaw_blend: float = 0.007
    smile_sigma: float = 0.013
    smile_vector: tuple[float, float, float] = (0.004, 0.005, -0.002)
    param_names: tuple[str, ...] = field(default=("jaw_open", "smile_L", "smile_R"))

    def to_dict(self) -> dict:
        """JSON-ready parameters (ground truth)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) m of neutral ``points`` (N, 3) m for ``params`` (3,)."""
        jaw, smile_l, smile_r = (float(p) for p in params)
        cl, cr = np.asarray(self.ch_left), np.asarray(self.ch_right)
        slope = (cl[1] - cr[1]) / (cl[0] - cr[0])
        line_y = cr[1] + slope * (points[:, 0] - cr[0])
        below = (line_y + self.lip_gap - points[:, 1]) / (self.lip_gap + self.jaw_blend)
        w = smoothstep(below)
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


def demo_performance(
    n_frames: int,
    fps: float,
    seed: int,
    *,
    head_rotation_amp_rad: float = 0.035,
    head_translation_amp_m: float = 0.003,
    head_center: tuple[float, float, float] = (0.0, 0.0, -0.09),
) -> Performance:
    """The demo sequence: jaw drop, then an asymmetric smile (left stronger), back to neutral.

    Expression timing is fixed in normalised time s = i / (T - 1); the rigid head motion is
    a sum of slow sinusoids (phases from ``seed``), zero at frame 0.
    """
    times = np.arange(n_frames) / fps
    s = np.linspace(0.0, 1.0, n_frames)
    params = np.stack(
        [bump(s, 0.03, 0.45), bump(s, 0.45, 0.97), 0.55 * bump(s, 0.52, 0.97)], axis=1
    )
    rng = np.random.default_rng(seed)
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
