"""Normalised Hill-type (Zajac 1989) muscle and tendon curves, as pure array functions.

Normalisation (SPEC section 4, seed 000 section 4.2): force by the maximum isometric force
F0, fibre length by the optimal fibre length l0, fibre velocity by the maximum shortening
velocity v_max (lengthening positive, shortening negative), tendon strain
eps = (l^T - l^T_slack) / l^T_slack.  Every function broadcasts over numpy arrays.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Force-velocity curve f(v) = c0 + c1 arctan(k (v - s)) for v >= -1 (0 below).  The seed's eq 8
#: is arctan-shaped but its coefficients are unreadable in the OCR; k and s were fitted to Hill's
#: concentric hyperbola (1 + v) / (1 - v / 0.25) on v in [-1, 0] with an eccentric plateau of 1.8
#: F0 (Zajac 1989, FitzHugh 1977); c0, c1 follow exactly from f(-1) = 0 and f(0) = 1.
FV_SLOPE = 4.9
FV_SHIFT = -0.056
FV_C1 = 1.0 / (np.arctan(-FV_SLOPE * FV_SHIFT) - np.arctan(-FV_SLOPE * (1.0 + FV_SHIFT)))
FV_C0 = 1.0 - FV_C1 * np.arctan(-FV_SLOPE * FV_SHIFT)

#: Tendon force-strain (seed eq 9): toe region 25 eps up to eps = 0.02 (force 0.5 F0), then
#: linear 37.5 eps - 0.25 (valid up to eps = 0.1, force 3.5 F0; extended linearly beyond).
TENDON_TOE_STRAIN = 0.02
TENDON_TOE_FORCE = 25.0 * TENDON_TOE_STRAIN


def passive_force_length(length: ArrayLike) -> NDArray[np.float64]:
    """Passive fibre force / F0 = 4 (l - 1)^2 for l > 1, else 0 (seed eq 6); l = l^M / l0."""
    stretch = np.maximum(np.asarray(length, dtype=float) - 1.0, 0.0)
    return 4.0 * stretch**2


def active_force_length(length: ArrayLike) -> NDArray[np.float64]:
    """Active isometric force / F0 at full activation (seed eq 7), capped at 1; l = l^M / l0.

    0.95 (exp(-(4 l - 4.1)^2) + 0.76 exp(-(5 l - 3.5)^2)); it reaches the cap 1 around l = 1.
    """
    x = np.asarray(length, dtype=float)
    f = 0.95 * (np.exp(-((4.0 * x - 4.1) ** 2)) + 0.76 * np.exp(-((5.0 * x - 3.5) ** 2)))
    return np.minimum(f, 1.0)


def force_velocity(velocity: ArrayLike) -> NDArray[np.float64]:
    """Force-velocity factor (arctan-shaped, seed eq 8): 0 at v <= -1, 1 at v = 0, -> 1.8.

    ``velocity`` is dl^M/dt / v_max (negative when shortening).  Smooth and increasing on v > -1.
    """
    v = np.asarray(velocity, dtype=float)
    f = FV_C0 + FV_C1 * np.arctan(FV_SLOPE * (v - FV_SHIFT))
    return np.where(v > -1.0, np.maximum(f, 0.0), 0.0)


def fibre_force(
    activation: ArrayLike,
    length: ArrayLike,
    velocity: ArrayLike,
    rest_vmax_fraction: float = 1.0,
) -> NDArray[np.float64]:
    """Fibre force / F0 = F_pas(l) + a F_iso(l) F_vel(v / s(a)) (seed eqs 3-8), inputs normalised.

    ``velocity`` is dl^M/dt divided by the maximum shortening velocity at full activation.  The
    seed's force-velocity coefficients depend on the activation (eq 8, unreadable in the OCR); we
    model that as a maximum shortening velocity that scales with activation,
    s(a) = f + (1 - f) a with f = ``rest_vmax_fraction`` (f = 1: no activation dependence).
    At a = 1 or v = 0 the fraction has no effect, so F(1, 1, 0) = 1.
    """
    a = np.asarray(activation, dtype=float)
    scale = rest_vmax_fraction + (1.0 - rest_vmax_fraction) * a
    v = np.asarray(velocity, dtype=float) / scale
    return passive_force_length(length) + a * active_force_length(length) * force_velocity(v)


def tendon_force(strain: ArrayLike) -> NDArray[np.float64]:
    """Tendon force / F0 from strain eps (seed eq 9); 0 for a slack tendon (eps <= 0)."""
    eps = np.asarray(strain, dtype=float)
    toe = 25.0 * eps
    linear = 37.5 * eps - 0.25
    return np.where(eps <= 0.0, 0.0, np.where(eps < TENDON_TOE_STRAIN, toe, linear))


def tendon_strain(force: ArrayLike) -> NDArray[np.float64]:
    """Tendon strain eps from force / F0: the exact inverse of :func:`tendon_force` (seed eq 13).

    F/25 below 0.5 F0, (F + 0.25)/37.5 above; 0 for F <= 0.
    """
    f = np.asarray(force, dtype=float)
    return np.where(f <= 0.0, 0.0, np.where(f < TENDON_TOE_FORCE, f / 25.0, (f + 0.25) / 37.5))
