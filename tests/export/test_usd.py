"""The USD file read back with pxr: units, axis, timing and every frame's points."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom, UsdValidation

from physanim.export.animation import MeshAnimation
from physanim.export.usd import ROOT, write_usd
from tests.export.conftest import three_modes


def validation_errors(stage: Usd.Stage) -> list[str]:
    """Every error of USD's own validators (usdchecker's) on ``stage``."""
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    return [e.GetMessage() for e in UsdValidation.ValidationContext(validators).Validate(stage)]


@pytest.mark.parametrize("suffix", [".usdc", ".usda"])
def test_usd_holds_every_frame_at_the_frame_rate(tmp_path: Path, suffix: str) -> None:
    anim = three_modes(frames=9, fps=24.0)
    path = write_usd(anim, tmp_path / f"fem{suffix}", doc="three modes")
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert stage.GetTimeCodesPerSecond() == 24.0 and stage.GetFramesPerSecond() == 24.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0, 8)
    assert stage.GetDefaultPrim().GetPath() == f"/{ROOT}"
    assert stage.GetRootLayer().documentation == "three modes"
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/{ROOT}/fem"))
    assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [3] * len(anim.faces)
    np.testing.assert_array_equal(
        np.asarray(mesh.GetFaceVertexIndicesAttr().Get()), anim.faces.ravel()
    )
    for attr in (mesh.GetPointsAttr(), mesh.GetNormalsAttr(), mesh.GetExtentAttr()):
        assert attr.GetTimeSamples() == list(range(anim.frames))
    for t in range(anim.frames):
        points = np.asarray(mesh.GetPointsAttr().Get(t))
        np.testing.assert_allclose(points, anim.points[t], rtol=0, atol=1e-6)
        np.testing.assert_array_equal(points, anim.points[t])  # float32 both: bit for bit
        np.testing.assert_array_equal(np.asarray(mesh.GetNormalsAttr().Get(t)), anim.normals[t])
        bounds = np.asarray(mesh.GetExtentAttr().Get(t))
        np.testing.assert_array_equal(bounds, [anim.points[t].min(0), anim.points[t].max(0)])
    # between frames, USD interpolates linearly: time code 2.5 lies half-way, at 2.5 / 24 s
    half = np.asarray(mesh.GetPointsAttr().Get(2.5))
    np.testing.assert_allclose(half, (anim.points[2] + anim.points[3]) / 2, atol=1e-8)
    assert validation_errors(stage) == []


def test_usd_validators_catch_a_stage_without_units(tmp_path: Path) -> None:
    """The validators above can fail: a stage with no up axis or units is reported."""
    stage = Usd.Stage.CreateNew(str(tmp_path / "bare.usda"))
    UsdGeom.Mesh.Define(stage, "/Bare")
    stage.SetDefaultPrim(stage.GetPrimAtPath("/Bare"))
    assert any("metersPerUnit" in e or "upAxis" in e for e in validation_errors(stage))


def test_an_existing_file_is_replaced(tmp_path: Path, modes: MeshAnimation) -> None:
    path = write_usd(three_modes(frames=3), tmp_path / "fem.usdc")
    write_usd(modes, path)
    stage = Usd.Stage.Open(str(path))  # held: a prim of a collected stage is invalid
    points = UsdGeom.Mesh(stage.GetPrimAtPath(f"/{ROOT}/fem")).GetPointsAttr()
    assert points.GetTimeSamples() == list(range(modes.frames))
