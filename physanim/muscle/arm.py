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


@dataclass(frozen=True)
class TorqueShortfall:
    """A stretch of time where the muscles cannot produce the torque at one joint.

    ``joint`` name; ``start_s``/``end_s`` first and last sample times, s; ``peak_Nm`` the
    largest missing torque (signed: positive = flexion missing), N m; ``peak_time_s`` when.
    """

    joint: str
    start_s: float
    end_s: float
    peak_Nm: float
    peak_time_s: float


def torque_shortfalls(
    result: ArmResult, joint_names: list[str], tol: float = 1e-6
) -> list[TorqueShortfall]:
    """Every stretch of consecutive samples with |torque_residual| > ``tol`` N m, per joint."""
    out = []
    for j, name in enumerate(joint_names):
        res = result.torque_residual[:, j]
        bad = np.abs(res) > tol
        edges = np.flatnonzero(np.diff(np.concatenate([[0], bad.astype(int), [0]])))
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            k = start + int(np.argmax(np.abs(res[start:stop])))
            out.append(
                TorqueShortfall(
                    name,
                    float(result.time[start]),
                    float(result.time[stop - 1]),
                    float(res[k]),
                    float(result.time[k]),
                )
            )
    return out


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
    fibre length and velocity set what a unit of activation buys), so they are alternated,
    starting from rigid tendons, until the tendon forces change by less than 1e-9 F0 (at most
    ``model.sharing_iterations`` passes); ``progress(done, total)`` is called after each pass.
    Static optimisation works on the reported activations themselves (objective and
    co-contraction floor); where the muscles cannot produce the torque it takes the closest
    torque they can, and ``torque_residual`` holds the missing torque.
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
    lower = np.full_like(paths.length, model.co_contraction)

    force = np.zeros_like(paths.length)
    activation = lower
    for k in range(model.sharing_iterations):
        state = fibre_state(paths.length, force, mc)
        vel = fibre_velocity(state.fibre_length, dt)

        def force_of(a: NDArray[np.float64], state=state, vel=vel) -> NDArray[np.float64]:
            return tendon_force_at(a, state, vel, mc, model)

        if joint_of_muscle is not None:
            new = seed_rule(paths.moment_arm, torque, force_of(lower), joint_of_muscle)
        else:
            activation, _ = static_optimisation(paths.moment_arm, torque, force_of, lower)
            new = force_of(activation)
        change = np.abs(new - force).max(initial=0.0) / mc.max_isometric_force.max()
        force = new
        if progress is not None:
            progress(k + 1, model.sharing_iterations)
        if change <= 1e-9:
            break

    state = fibre_state(paths.length, force, mc)
    vel = fibre_velocity(state.fibre_length, dt)
    if joint_of_muscle is not None:
        activation, shortfall = solve_activation(force, state, vel, mc, model)
    else:
        shortfall = np.zeros_like(force)  # static optimisation asks only for reachable forces
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
