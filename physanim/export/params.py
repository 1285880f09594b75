"""Parameters of the ``export`` stage."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field


class ExportParams(BaseModel):
    """What the export writes beside the USD files (every file in metres, +y up, at the
    capture frame rate)."""

    model_config = ConfigDict(extra="forbid")
    gltf_tolerance_mm: float = Field(
        0.1,
        gt=0.0,
        le=10.0,
        description="largest RMS distance, mm, over frames and vertices, of the glTF's "
        "morph-target animation from the full one: sets how many targets it has",
    )
    gltf_max_targets: int = Field(
        32, ge=1, le=128, description="most morph targets in a glTF file (count)"
    )
    gltf_quantized: bool = Field(
        True,
        description="morph targets as 16-bit positions (in units of the node's scale) and "
        "8-bit normals (KHR_mesh_quantization, read by three.js, Babylon.js and Blender): "
        "half the size of float targets",
    )
    alembic: bool = Field(
        False,
        description="also write Alembic (.abc) files, through Blender's Python module "
        "(make setup-blender; about 8 s per variant on the demo)",
    )
