"""Activation estimation from tendon forces through the tendon and fibre model (seed eqs 13-18).

Per muscle and time step: tendon force -> tendon strain (eq 13) -> tendon length (eq 14) ->
fibre length with constant-width pennation (eq 17) -> fibre velocity by finite difference
(eq 18) -> the activation whose fibre force along the tendon equals the tendon force, found by
vectorised bisection (the seed decrements a from 1 in steps of 0.001).
Arrays are (T, m): T time samples, m muscles.  Forces in N, lengths in m, velocities in m/s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from physanim.muscle.curves import fibre_force, tendon_strain
from physanim.muscle.params import ArmParams, ModelParams

BISECTION_STEPS = 60  # halves [0, 1] down to ~1e-18, below float resolution
GAP_TOL = 1e-9  # gaps below this fraction of F0 are rounding, reported as 0


@dataclass(frozen=True)
class MuscleConstants:
    """Per-muscle constants, each (m,): l0 (m), tendon slack (m), F0 (N), fibre width w (m).

    w = l0 sin(alpha0) is the constant width of a pennated muscle (seed eq 17).
    """

    optimal_fibre_length: NDArray[np.float64]
    tendon_slack_length: NDArray[np.float64]
    max_isometric_force: NDArray[np.float64]
    width: NDArray[np.float64]

    @classmethod
    def from_arm(cls, arm: ArmParams) -> MuscleConstants:
        """Collect the constants of ``arm.muscles`` in order."""
        l0 = np.array([m.optimal_fibre_length for m in arm.muscles])
        return cls(
            optimal_fibre_length=l0,
            tendon_slack_length=np.array([m.tendon_slack_length for m in arm.muscles]),
            max_isometric_force=np.array([m.max_isometric_force for m in arm.muscles]),
            width=l0 * np.sin(np.radians([m.pennation_deg for m in arm.muscles])),
        )


@dataclass(frozen=True)
class FibreState:
    """Tendon and fibre geometry for given tendon forces, each (T, m).

    tendon_length, fibre_length in m; cos_pennation unitless (0 when the fibre stands
    perpendicular to the tendon, i.e. the musculotendon path is shorter than the tendon).
    """

    tendon_length: NDArray[np.float64]
    fibre_length: NDArray[np.float64]
    cos_pennation: NDArray[np.float64]


def fibre_state(
    musculotendon_length: ArrayLike, tendon_force: ArrayLike, mc: MuscleConstants
) -> FibreState:
    """Tendon length (1 + eps) l_slack (eqs 13-14) and fibre length sqrt((l^MT - l^T)^2 + w^2).

    musculotendon_length (T, m) m, tendon_force (T, m) N.
    """
    f = np.asarray(tendon_force, dtype=float)
    eps = tendon_strain(f / mc.max_isometric_force)
    l_t = (1.0 + eps) * mc.tendon_slack_length
    along = np.maximum(np.asarray(musculotendon_length, dtype=float) - l_t, 0.0)
    l_m = np.sqrt(along**2 + mc.width**2)
    return FibreState(l_t, l_m, along / l_m)


def fibre_velocity(fibre_length: ArrayLike, dt: float) -> NDArray[np.float64]:
    """dl^M/dt (T, m) in m/s by finite differences over time (eq 18), second-order central.

    The seed uses the backward difference (l(t) - l(t - 1)) / dt; central differences
    (one-sided at the ends) are second-order accurate at no extra cost.
    """
    l_m = np.asarray(fibre_length, dtype=float)
    if l_m.shape[0] < 2:
        raise ValueError(f"fibre_velocity: need at least 2 time samples, got {l_m.shape[0]}")
    return np.gradient(l_m, dt, axis=0, edge_order=2 if l_m.shape[0] > 2 else 1)


def tendon_force_at(
    activation: ArrayLike,
    state: FibreState,
    fibre_velocity: ArrayLike,
    mc: MuscleConstants,
    model: ModelParams,
) -> NDArray[np.float64]:
    """Fibre force along the tendon, F0 F^M(a, l^M/l0, v^M/v_max) cos(alpha), (T, m) N."""
    l_n = state.fibre_length / mc.optimal_fibre_length
    v_n = np.asarray(fibre_velocity, dtype=float) / (
        model.max_shortening_velocity * mc.optimal_fibre_length
    )
    f = fibre_force(activation, l_n, v_n, model.rest_vmax_fraction)
    return mc.max_isometric_force * f * state.cos_pennation


def solve_activation(
    tendon_force: ArrayLike,
    state: FibreState,
    fibre_velocity: ArrayLike,
    mc: MuscleConstants,
    model: ModelParams,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Activation a in [0, 1] whose fibre force along the tendon equals the tendon force.

    The fibre force is increasing in a, so bisection on [0, 1] brackets the root.  Where no a in
    [0, 1] suffices, a is clipped and the gap reported.  Returns activation (T, m) and
    shortfall (T, m) N = required tendon force - force the fibre delivers at that activation:
    positive where the muscle is too weak even at a = 1, negative where its passive force
    alone (a = 0) exceeds the requirement, 0 where the requirement is met (to 1e-9 F0).
    """
    f_req = np.asarray(tendon_force, dtype=float)

    def force(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return tendon_force_at(a, state, fibre_velocity, mc, model)

    lo, hi = np.zeros_like(f_req), np.ones_like(f_req)
    for _ in range(BISECTION_STEPS):
        mid = 0.5 * (lo + hi)
        below = force(mid) < f_req
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    a = 0.5 * (lo + hi)
    f_max, f_min = force(np.ones_like(f_req)), force(np.zeros_like(f_req))
    a = np.where(f_req >= f_max, 1.0, np.where(f_req <= f_min, 0.0, a))
    gap = np.where(f_req > f_max, f_req - f_max, np.where(f_req < f_min, f_req - f_min, 0.0))
    shortfall = np.where(np.abs(gap) > GAP_TOL * mc.max_isometric_force, gap, 0.0)
    return a, shortfall
