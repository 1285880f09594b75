"""Stage ``muscles``: torques, muscle forces and activations of every arm condition."""

from __future__ import annotations

from physanim.muscle.params import ArmConditions
from physanim.pipeline import StageContext, StageSpec


def compute(ctx: StageContext) -> None:
    """Solve each condition; arrays under ``<condition>/<field>`` (time axis first)."""
    from physanim.muscle.arm import solve_arm

    params: ArmConditions = ctx.params  # type: ignore[assignment]
    studies = params.resolved()
    report = ctx.progress("muscles")
    peaks = {}
    for i, (name, study) in enumerate(studies.items()):
        result = solve_arm(study)
        ctx.write_record(result, prefix=name)
        peaks[name] = {
            m.name: round(float(result.activation[:, j].max()), 4)
            for j, m in enumerate(study.arm.muscles)
        }
        report(i + 1, len(studies))
    ctx.summary["peak_activation"] = peaks
    ctx.summary["max_torque_residual_Nm"] = max(
        float(abs(ctx.out[f"{n}/torque_residual"][...]).max()) for n in studies
    )


SPEC = StageSpec(
    name="muscles",
    upstream=(),
    params=ArmConditions,
    version="1",
    compute=compute,
    doc="inverse dynamics, force sharing and Zajac activations per condition",
)
