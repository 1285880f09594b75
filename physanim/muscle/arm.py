"""The muscle-driven arm end to end: motion -> torques -> muscle forces -> activations.

Seed 000 (SPEC section 4): prescribed joint motion, joint torques by Newton-Euler inverse
dynamics (physanim.dynamics), straight-line muscle geometry, force sharing (the seed's rule or
static optimisation), then activations through the tendon and fibre model.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from physanim.dynamics import inverse_dynamics
from physanim.muscle.activation import (
    MuscleConstants,
    fibre_state,
    fibre_velocity,
    solve_activation,
    tendon_force_at,
)
from physanim.muscle.geometry import arm_figure, body_frames, muscle_paths
from physanim.muscle.params import ArmParams, ArmStudyParams
from physanim.muscle.sharing import seed_rule, static_optimisation
from physanim.muscle.trajectory import seed_trajectory


@dataclass(frozen=True)
class ArmResult:
    """One condition over time: T samples, n joints, m muscles (SI units).

    time (T,) s; q, qd, qdd (T, n) rad, rad/s, rad/s^2; torque (T, n) N m from inverse
    dynamics; bodies (T, n + 2, 2) m: base, joints and hand positions.
    Per muscle, (T, m): force (tendon force asked of the muscle, N), activation in [0, 1],
    fibre_length, tendon_length, musculotendon_length (m), fibre_velocity (m/s, shortening
    negative), shortfall (N: asked minus delivered, see ``solve_activation``); origin and
    insertion (T, m, 2) m; moment_arm (T, m, n) m.
    torque_residual (T, n) N m: inverse-dynamics torque minus the torque of the forces the
    muscles deliver (0 wherever the muscles can produce the motion).
    """

    time: NDArray[np.float64]
    q: NDArray[np.float64]
    qd: NDArray[np.float64]
    qdd: NDArray[np.float64]
    torque: NDArray[np.float64]
    bodies: NDArray[np.float64]
    force: NDArray[np.float64]
    activation: NDArray[np.float64]
    fibre_length: NDArray[np.float64]
    tendon_length: NDArray[np.float64]
    musculotendon_length: NDArray[np.float64]
    fibre_velocity: NDArray[np.float64]
    shortfall: NDArray[np.float64]
    origin: NDArray[np.float64]
    insertion: NDArray[np.float64]
    moment_arm: NDArray[np.float64]
    torque_residual: NDArray[np.float64]


def crossed_joint(arm: ArmParams) -> NDArray[np.int_]:
    """The joint each muscle crosses (m,); raises ValueError for a biarticular muscle."""
    joints = []
    for m in arm.muscles:
        lo, hi = sorted((arm.body_index(m.origin_body), arm.body_index(m.insertion_body)))
        if hi - lo != 1:
            raise ValueError(
                f"muscle {m.name!r} crosses joints {lo}..{hi - 1}; the seed rule needs muscles "
                "that cross one joint each (use force_sharing: static_optimisation)"
            )
        joints.append(lo)
    return np.array(joints)


def solve_arm(
    study: ArmStudyParams, progress: Callable[[int, int], None] | None = None
) -> ArmResult:
    """Torques, muscle forces and activations of one condition (arm, motion, model).

    Force sharing and the fibre state depend on each other (tendon stretch moves the fibre;
    fibre length and velocity set what a unit of activation buys), so they are alternated
    ``model.sharing_iterations`` times starting from rigid tendons; ``progress(done, total)``
    is called after each pass.
    """
    arm, motion, model = study.arm, study.motion, study.model
    n_t = int(round(motion.duration * motion.sample_rate)) + 1
    time = np.linspace(0.0, motion.duration, n_t)
    dt = time[1] - time[0]
    q, qd, qdd = seed_trajectory(
        time, np.radians(motion.start_deg), np.radians(motion.range_deg), motion.duration
    )
    fig = arm_figure(arm)
    torque = inverse_dynamics(fig, q, qd, qdd)
    paths = muscle_paths(arm, q)
    mc = MuscleConstants.from_arm(arm)
    joint_of_muscle = crossed_joint(arm) if model.force_sharing == "seed_rule" else None

    force = np.zeros_like(paths.length)
    for k in range(model.sharing_iterations):
        state = fibre_state(paths.length, force, mc)
        vel = fibre_velocity(state.fibre_length, dt)
        floor = tendon_force_at(np.zeros_like(force), state, vel, mc, model)
        gain = tendon_force_at(np.ones_like(force), state, vel, mc, model) - floor
        minimum = floor + model.co_contraction * gain
        if joint_of_muscle is not None:
            force = seed_rule(paths.moment_arm, torque, minimum, joint_of_muscle)
        else:
            force = static_optimisation(paths.moment_arm, torque, floor, gain, minimum)
        if progress is not None:
            progress(k + 1, model.sharing_iterations)

    state = fibre_state(paths.length, force, mc)
    vel = fibre_velocity(state.fibre_length, dt)
    activation, shortfall = solve_activation(force, state, vel, mc, model)
    delivered = force - shortfall
    residual = torque - np.einsum("tmn,tm->tn", paths.moment_arm, delivered)
    bodies, _ = body_frames(fig, q)
    return ArmResult(
        time=time,
        q=q,
        qd=qd,
        qdd=qdd,
        torque=torque,
        bodies=bodies,
        force=force,
        activation=activation,
        fibre_length=state.fibre_length,
        tendon_length=state.tendon_length,
        musculotendon_length=paths.length,
        fibre_velocity=vel,
        shortfall=shortfall,
        origin=paths.origin,
        insertion=paths.insertion,
        moment_arm=paths.moment_arm,
        torque_residual=residual,
    )
