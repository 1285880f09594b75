"""A mesh animation as a USD stage (``usd-core``): point time samples at the frame rate."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from physanim.export.animation import MeshAnimation

#: The prim every exported stage has as its default prim; the mesh is ``/Face/<name>``.
ROOT = "Face"


def write_usd(animation: MeshAnimation, path: Path, doc: str = "") -> Path:
    """Write ``animation`` to ``path`` (.usdc binary crate, .usda text) and return it.

    The stage states its units and timing: metersPerUnit 1, upAxis Y, timeCodesPerSecond
    and framesPerSecond the animation's fps, time codes 0 .. T-1 (frame i at time code i).
    ``/Face`` (Xform, default prim, kind component) holds the Mesh ``/Face/<name>``: the
    triangles, no subdivision, and per time code its points (m), vertex normals and extent;
    ``doc`` becomes the layer's documentation string.
    """
    from pxr import Kind, Sdf, Usd, UsdGeom, Vt

    path = Path(path)
    path.unlink(missing_ok=True)  # CreateNew refuses an existing layer
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(animation.fps)
    stage.SetFramesPerSecond(animation.fps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(animation.frames - 1)
    root = UsdGeom.Xform.Define(stage, Sdf.Path(f"/{ROOT}"))
    Usd.ModelAPI(root.GetPrim()).SetKind(Kind.Tokens.component)
    stage.SetDefaultPrim(root.GetPrim())
    if doc:
        stage.GetRootLayer().documentation = doc

    mesh = UsdGeom.Mesh.Define(stage, root.GetPath().AppendChild(animation.name))
    faces = animation.faces.astype(np.int32)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.ravel()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    points, normals = mesh.CreatePointsAttr(), mesh.CreateNormalsAttr()
    extent = mesh.CreateExtentAttr()
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    bounds = np.stack([animation.points.min(axis=1), animation.points.max(axis=1)], axis=1)
    frames = zip(animation.points, animation.normals, bounds, strict=True)
    for t, (p, n, b) in enumerate(frames):
        points.Set(Vt.Vec3fArray.FromNumpy(p), t)
        normals.Set(Vt.Vec3fArray.FromNumpy(n), t)
        extent.Set(Vt.Vec3fArray.FromNumpy(b), t)
    stage.GetRootLayer().Save()
    return path
