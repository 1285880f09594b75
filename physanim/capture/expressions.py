"""Analytic expression fields beyond the demo's jaw drop and smile, and their sum.

Each field implements ``physanim.capture.performance.ExpressionModel``: neutral actor-frame
points (N, 3) m and parameters (P,) in [0, 1] -> displacements (N, 3) m, exactly zero at
zero parameters, C1 in space (C1 smoothsteps and Gaussians), and is placed from the
actor's painted markers (``physanim.capture.markers``). Actor frame: +x the actor's left,
+y up, +z out of the face, towards the camera (the view direction is -z).

Fields (magnitudes at parameter 1; lengths m, angles rad):

* :class:`BrowField` ``brow_raise``: the brows and forehead slide up by ``lift`` (6 mm
  at the medial brows), weight ``smoothstep`` from the lower lids (0) to the brows (1),
  falling to ``1 - forehead_drop`` at the forehead marker, times a Gaussian across x.
  ``frown``: each medial brow moves down and towards the midline by ``frown_vector``
  (3 mm each way) with a Gaussian falloff around ``brow_in_L``/``brow_in_R``.
* :class:`MouthField` ``lip_pucker`` / ``lip_funnel`` / ``lip_press``: one weight
  ``w`` over the lips (1 on an elliptic plateau around the middle of the mouth, C1 down to
  0 outside ``r_out`` half-widths); per expression, ``forward`` m along +z, horizontal
  draw-in of the mouth towards its middle (strain ``draw_in``) and a vertical parting
  ``part`` m of each lip away from the lip line (negative: lips pressed together). Pucker:
  9 mm forward, draw-in 0.5; funnel: 6 mm forward, draw-in 0.3, lips part by 3 mm each;
  press: 2 mm back, lips 1.5 mm towards each other, corners out.
* :class:`JawSideField` ``jaw_left`` / ``jaw_right``: the jaw region (the demo's jaw
  weight) rotates about the vertical axis through the jaw pivot, the chin towards that side
  (0.12 rad: ~6 mm at the chin).
* :class:`CheekPuffField` ``cheek_puff``: cheeks (Gaussians around ``cheek_low_L/R``,
  7 mm) and lips (the mouth weight, 3 mm) move outwards, radially from a vertical axis
  inside the mouth (mostly forwards, along the view direction).
* :class:`NoseWrinkleField` ``nose_wrinkle``: the nose wings rise 3 mm, the upper lip 2 mm,
  the skin of the nasal bridge slides 2 mm down (Gaussians).

The one-sided smile is the demo field's ``smile_L`` (or ``smile_R``) alone.
:func:`face_field` sums all fields with one parameter each (:class:`CompositeField`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation

from physanim.capture.performance import (
    JAW_PIVOT,
    AnalyticFaceField,
    ExpressionModel,
    JsonFields,
    jaw_weight,
    lip_line_y,
    smoothstep,
)

Vec3 = tuple[float, float, float]


def gaussian(points: np.ndarray, center: np.ndarray, sigma: float) -> np.ndarray:
    """Isotropic Gaussian weight (N,) of ``points`` (N, 3) m around ``center`` (3,) m, std
    ``sigma`` m; 1 at the centre."""
    return np.exp(-((points - center) ** 2).sum(axis=1) / (2.0 * sigma**2))


def _vec(v: np.ndarray) -> Vec3:
    """A marker position (3,) m as a JSON-friendly tuple of floats."""
    return (float(v[0]), float(v[1]), float(v[2]))


def _mirror(v: Sequence[float]) -> np.ndarray:
    """A vector (3,) of the actor's left side, mirrored to the right (x negated)."""
    return np.asarray(v) * np.array([-1.0, 1.0, 1.0])


@dataclass(frozen=True)
class BrowField(JsonFields):
    """Brow raise and frown; see the module docstring."""

    brow_in_left: Vec3
    brow_in_right: Vec3
    eye_y: float
    brow_y: float
    forehead_y: float
    center_x: float
    lift: float = 0.006
    width_sigma: float = 0.037
    forehead_drop: float = 0.5
    frown_sigma: float = 0.009
    frown_vector: Vec3 = (-0.003, -0.003, 0.0)
    param_names: tuple[str, ...] = field(default=("brow_raise", "frown"))

    @classmethod
    def from_markers(cls, m: Mapping[str, np.ndarray]) -> BrowField:
        """Placed from the lower lids (pi), brows, glabella and forehead markers."""
        brows = [m[f"brow_{k}_{s}"][1] for k in ("in", "mid", "out") for s in "LR"]
        return cls(
            brow_in_left=_vec(m["brow_in_L"]),
            brow_in_right=_vec(m["brow_in_R"]),
            eye_y=float(0.5 * (m["pi_L"][1] + m["pi_R"][1])),
            brow_y=float(np.mean(brows)),
            forehead_y=float(m["forehead"][1]),
            center_x=float(m["glabella"][0]),
        )

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) m of ``points`` (N, 3) m for (brow_raise, frown)."""
        raise_, frown = (float(p) for p in params)
        x, y = points[:, 0], points[:, 1]
        up = smoothstep((y - self.eye_y) / (self.brow_y - self.eye_y))
        up = up * (
            1.0
            - self.forehead_drop * smoothstep((y - self.brow_y) / (self.forehead_y - self.brow_y))
        )
        up = up * np.exp(-((x - self.center_x) ** 2) / (2.0 * self.width_sigma**2))
        disp = np.zeros_like(points)
        disp[:, 1] = raise_ * self.lift * up
        for center, vec in (
            (self.brow_in_left, np.asarray(self.frown_vector)),
            (self.brow_in_right, _mirror(self.frown_vector)),
        ):
            disp += frown * gaussian(points, np.asarray(center), self.frown_sigma)[:, None] * vec
        return disp


@dataclass(frozen=True)
class MouthWeight(JsonFields):
    """Weight (N,) over the lips: 1 where the elliptic radius ``r`` (in units of the half
    mouth width across, ``half_height`` m up and down from the lip line) is below ``r_in``,
    0 beyond ``r_out``, C1 smoothstep between; it depends on x and y only."""

    ch_left: Vec3
    ch_right: Vec3
    half_height: float = 0.009
    r_in: float = 0.35
    r_out: float = 1.6

    @property
    def center_x(self) -> float:
        """x (m) of the middle of the mouth."""
        return 0.5 * (self.ch_left[0] + self.ch_right[0])

    @property
    def half_width(self) -> float:
        """Half the corner-to-corner distance in x; m."""
        return 0.5 * abs(self.ch_left[0] - self.ch_right[0])

    def above_line(self, points: np.ndarray) -> np.ndarray:
        """Height (N,) m of ``points`` (N, 3) m above the lip line."""
        return points[:, 1] - lip_line_y(
            points, np.asarray(self.ch_left), np.asarray(self.ch_right)
        )

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """The weight (N,) of ``points`` (N, 3) m."""
        r = np.hypot(
            (points[:, 0] - self.center_x) / self.half_width,
            self.above_line(points) / self.half_height,
        )
        return 1.0 - smoothstep((r - self.r_in) / (self.r_out - self.r_in))


@dataclass(frozen=True)
class MouthField(JsonFields):
    """Lip pucker, funnel and press; see the module docstring. ``forward`` (m), ``draw_in``
    (1) and ``part`` (m) hold one value per parameter; ``part_width`` m is the tanh width of
    the lips' parting across the lip line."""

    weight: MouthWeight
    forward: Vec3 = (0.009, 0.006, -0.002)
    draw_in: Vec3 = (0.5, 0.3, -0.1)
    part: Vec3 = (0.0, 0.003, -0.0015)
    part_width: float = 0.003
    param_names: tuple[str, ...] = field(default=("lip_pucker", "lip_funnel", "lip_press"))

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) m of ``points`` (N, 3) m for (lip_pucker, lip_funnel,
        lip_press)."""
        a = np.asarray(params, dtype=np.float64)
        w = self.weight(points)
        side = np.tanh(self.weight.above_line(points) / self.part_width)
        disp = np.empty_like(points)
        disp[:, 0] = -(a @ self.draw_in) * (points[:, 0] - self.weight.center_x) * w
        disp[:, 1] = (a @ self.part) * side * w
        disp[:, 2] = (a @ self.forward) * w
        return disp


@dataclass(frozen=True)
class JawSideField(JsonFields):
    """Sideways jaw; see the module docstring."""

    ch_left: Vec3
    ch_right: Vec3
    jaw_pivot: Vec3 = JAW_PIVOT
    max_angle: float = 0.12
    param_names: tuple[str, ...] = field(default=("jaw_left", "jaw_right"))

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) m of ``points`` (N, 3) m for (jaw_left, jaw_right)."""
        left, right = (float(p) for p in params)
        w = jaw_weight(points, np.asarray(self.ch_left), np.asarray(self.ch_right))
        # about +y, a positive angle turns +z (the chin) towards +x (the actor's left)
        rot = Rotation.from_rotvec([0.0, (left - right) * self.max_angle, 0.0]).as_matrix()
        rel = points - np.asarray(self.jaw_pivot)
        return w[:, None] * (rel @ rot.T - rel)


@dataclass(frozen=True)
class CheekPuffField(JsonFields):
    """Cheek puff; see the module docstring. ``axis_z`` m: depth of the vertical axis (at
    the mouth's middle x) the cheeks and lips move away from; the direction's length is
    ``rho / sqrt(rho^2 + axis_core^2)`` (rho: distance from the axis), 1 to within 1 % at
    the skin and smooth everywhere (zero on the axis)."""

    cheek_left: Vec3
    cheek_right: Vec3
    weight: MouthWeight
    axis_z: float
    cheek: float = 0.007
    cheek_sigma: float = 0.012
    lips: float = 0.003
    axis_core: float = 0.003
    param_names: tuple[str, ...] = field(default=("cheek_puff",))

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) m of ``points`` (N, 3) m for (cheek_puff,)."""
        radial = points - np.array([self.weight.center_x, 0.0, self.axis_z])
        radial[:, 1] = 0.0
        radial /= np.sqrt((radial**2).sum(axis=1, keepdims=True) + self.axis_core**2)
        amount = self.lips * self.weight(points) + self.cheek * (
            gaussian(points, np.asarray(self.cheek_left), self.cheek_sigma)
            + gaussian(points, np.asarray(self.cheek_right), self.cheek_sigma)
        )
        return float(params[0]) * amount[:, None] * radial


@dataclass(frozen=True)
class NoseWrinkleField(JsonFields):
    """Nose wrinkle; see the module docstring. Per spot (nose wings, upper lip, bridge):
    centre m, std m and displacement m."""

    wing_left: Vec3
    wing_right: Vec3
    upper_lip: Vec3
    bridge: Vec3
    wing_vector: Vec3 = (0.0, 0.003, 0.0)
    wing_sigma: float = 0.006
    lip_vector: Vec3 = (0.0, 0.002, 0.0)
    lip_sigma: float = 0.007
    bridge_vector: Vec3 = (0.0, -0.002, 0.0)
    bridge_sigma: float = 0.008
    param_names: tuple[str, ...] = field(default=("nose_wrinkle",))

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) m of ``points`` (N, 3) m for (nose_wrinkle,)."""
        disp = np.zeros_like(points)
        for center, sigma, vec in (
            (self.wing_left, self.wing_sigma, self.wing_vector),
            (self.wing_right, self.wing_sigma, self.wing_vector),
            (self.upper_lip, self.lip_sigma, self.lip_vector),
            (self.bridge, self.bridge_sigma, self.bridge_vector),
        ):
            g = gaussian(points, np.asarray(center), sigma)
            disp += g[:, None] * np.asarray(vec)
        return float(params[0]) * disp


@dataclass(frozen=True)
class CompositeField:
    """Sum of expression models. Its ``param_names`` select some of the components'
    parameters (each name belongs to exactly one component); the others stay 0."""

    components: tuple[ExpressionModel, ...]
    param_names: tuple[str, ...]

    def __post_init__(self) -> None:
        names = [n for c in self.components for n in c.param_names]
        if len(set(names)) != len(names):
            raise ValueError(f"components share parameter names: {names}")
        unknown = [n for n in self.param_names if n not in names]
        if unknown or len(set(self.param_names)) != len(self.param_names):
            raise ValueError(
                f"parameters {list(self.param_names)}: each must be one of {names}, once"
            )

    def select(self, names: Sequence[str]) -> CompositeField:
        """The same components driven by the parameters ``names`` only."""
        return replace(self, param_names=tuple(names))

    def displacement(self, points: np.ndarray, params: np.ndarray) -> np.ndarray:
        """Displacement (N, 3) m of ``points`` (N, 3) m for ``params`` (len(param_names),);
        components whose parameters are all 0 are skipped (they move nothing)."""
        value = dict(zip(self.param_names, np.asarray(params, dtype=np.float64), strict=True))
        disp = np.zeros(points.shape)
        for comp in self.components:
            p = np.array([value.get(n, 0.0) for n in comp.param_names])
            if p.any():
                disp += comp.displacement(points, p)
        return disp

    def to_dict(self) -> dict:
        """JSON-ready parameters (ground truth): the selected names and each component's."""
        return {
            "param_names": list(self.param_names),
            "components": {type(c).__name__: c.to_dict() for c in self.components},
        }


def face_field(markers: Mapping[str, np.ndarray]) -> CompositeField:
    """Every expression field placed from neutral marker positions (name -> (3,) m), all
    parameters selected: the demo's (jaw_open, smile_L, smile_R) then the fields above."""
    ch_l, ch_r = _vec(markers["ch_L"]), _vec(markers["ch_R"])
    mouth = MouthWeight(ch_l, ch_r)
    components: tuple[ExpressionModel, ...] = (
        AnalyticFaceField(ch_left=ch_l, ch_right=ch_r),
        BrowField.from_markers(markers),
        MouthField(mouth),
        JawSideField(ch_l, ch_r),
        CheekPuffField(
            cheek_left=_vec(markers["cheek_low_L"]),
            cheek_right=_vec(markers["cheek_low_R"]),
            weight=mouth,
            axis_z=0.5 * (ch_l[2] + ch_r[2]) - 0.03,
        ),
        NoseWrinkleField(
            wing_left=_vec(markers["al_L"]),
            wing_right=_vec(markers["al_R"]),
            upper_lip=_vec(0.5 * (markers["cphs_L"] + markers["cphs_R"])),
            bridge=_vec(markers["nose_bridge"]),
        ),
    )
    return CompositeField(components, tuple(n for c in components for n in c.param_names))
