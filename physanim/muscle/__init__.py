"""Muscle-driven arm (seed 000, SPEC section 4): Zajac Hill-type muscles with tendons, force
sharing, activation estimation and volume-preserving spindle shapes.

Entry point: :func:`physanim.muscle.arm.solve_arm` with an
:class:`physanim.muscle.params.ArmStudyParams` (configs/arm/*.yaml).
"""
