"""Stage ``muscles``: torques, muscle forces and activations of every arm condition."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from physanim.muscle.arm import ArmResult
from physanim.muscle.params import ArmConditions
from physanim.pipeline import StageContext, StageOutput, StageSpec

if TYPE_CHECKING:
    from physanim.muscle.arm import TorqueShortfall


@dataclass(frozen=True)
class MusclesOutput(StageOutput):
    """Every arm condition solved: condition name -> :class:`~physanim.muscle.arm.ArmResult`
    (time axis first, SI units), stored as one group per condition."""

    conditions: dict[str, ArmResult] = field(metadata={"stored": ""})


def shortfall_warning(condition: str, gap: TorqueShortfall) -> str:
    """One line naming the condition, joint, time span and the missing torque."""
    kind = "flexion" if gap.peak_Nm > 0 else "extension"
    return (
        f"arm condition {condition!r}: the muscles cannot produce the torque at {gap.joint} from "
        f"{1000 * gap.start_s:.0f} to {1000 * gap.end_s:.0f} ms; up to {abs(gap.peak_Nm):.2f} "
        f"N m of {kind} missing (at {1000 * gap.peak_time_s:.0f} ms)"
    )


def compute(params: ArmConditions, ctx: StageContext[ArmConditions]) -> MusclesOutput:
    """Solve each condition; arrays under ``<condition>/<field>`` (time axis first).

    The summary flags torques the muscles cannot produce (``feasible``, ``infeasible`` spans
    per condition) and ``warnings`` carries one line per span for the CLI.
    """
    from physanim.muscle.arm import solve_arm, torque_shortfalls

    studies = params.resolved()
    report = ctx.progress("muscles")
    peaks, infeasible, warnings = {}, {}, []
    results = {}
    for i, (name, study) in enumerate(studies.items()):
        result = results[name] = solve_arm(study)
        peaks[name] = {
            m.name: round(float(result.activation[:, j].max()), 4)
            for j, m in enumerate(study.arm.muscles)
        }
        joints = [f"J{j} ({link.name})" for j, link in enumerate(study.arm.links)]
        gaps = torque_shortfalls(result, joints)
        if gaps:
            infeasible[name] = [
                {
                    "joint": g.joint,
                    "from_ms": round(1000 * g.start_s, 1),
                    "to_ms": round(1000 * g.end_s, 1),
                    "peak_missing_Nm": round(g.peak_Nm, 4),
                }
                for g in gaps
            ]
            warnings += [shortfall_warning(name, g) for g in gaps]
        report(i + 1, len(studies))
    summary = {
        "peak_activation": peaks,
        "max_torque_residual_Nm": max(
            float(abs(r.torque_residual).max()) for r in results.values()
        ),
        "feasible": not infeasible,
        "infeasible": infeasible,
    }
    if warnings:
        summary["warnings"] = warnings
    return MusclesOutput(results, summary=summary)


SPEC = StageSpec.typed(
    "muscles",
    compute,
    version="2",
    doc="inverse dynamics, force sharing and Zajac activations per condition",
)
