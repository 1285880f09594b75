"""The glTF binary: its morph basis, its layout parsed here byte by byte, and (where it is
installed) the Khronos glTF validator's verdict."""

from __future__ import annotations

import json
import os
import shutil
import struct
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from physanim.export.animation import MeshAnimation
from physanim.export.gltf import morph_animation, read_glb, rms_distance, write_glb
from physanim.export.usd import write_usd
from tests.commands import ROOT
from tests.export.conftest import three_modes

#: The Khronos glTF validator (npm package gltf-validator; ``make setup`` installs it here
#: when npm is present), or GLTF_VALIDATOR naming its folder.
VALIDATOR = Path(
    os.environ.get("GLTF_VALIDATOR", ROOT / ".venv/gltf-validator/node_modules/gltf-validator")
)
COMPONENTS = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def parse_glb(path: Path) -> tuple[dict[str, Any], bytes]:
    """(JSON document, binary chunk) of a .glb, its header and chunk framing checked."""
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_length, json_type = struct.unpack_from("<I4s", data, 12)
    assert json_type == b"JSON" and json_length % 4 == 0
    doc = json.loads(data[20 : 20 + json_length])
    bin_length, bin_type = struct.unpack_from("<I4s", data, 20 + json_length)
    assert bin_type == b"BIN\x00" and bin_length % 4 == 0
    assert 28 + json_length + bin_length == len(data)
    return doc, data[28 + json_length :]


def accessor(doc: dict[str, Any], blob: bytes, index: int) -> np.ndarray:
    """(count, width) values of accessor ``index`` as stored (not normalized), its bounds
    within its buffer view and its alignment checked."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype, width = np.dtype(COMPONENTS[acc["componentType"]]), WIDTHS[acc["type"]]
    element = dtype.itemsize * width
    stride = view.get("byteStride", element)
    offset = acc.get("byteOffset", 0)
    assert view["byteOffset"] % 4 == 0 and offset % dtype.itemsize == 0
    assert view["byteOffset"] + view["byteLength"] <= doc["buffers"][0]["byteLength"]
    assert offset + stride * (acc["count"] - 1) + element <= view["byteLength"]
    if view.get("target") == 34962:  # vertex attributes: 4-byte aligned elements
        assert stride % 4 == 0 and stride >= element
    start = view["byteOffset"] + offset
    return np.ndarray((acc["count"], width), dtype, blob, start, (stride, dtype.itemsize)).copy()


def dequantized(doc: dict[str, Any], blob: bytes, index: int) -> np.ndarray:
    """Accessor ``index`` as float64, normalized integers mapped to [-1, 1] (glTF's rule)."""
    values = accessor(doc, blob, index).astype(np.float64)
    acc = doc["accessors"][index]
    if acc.get("normalized"):
        values = np.maximum(values / {5120: 127, 5122: 32767}[acc["componentType"]], -1.0)
    return values


def decoded_animation(path: Path) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """(key times (T,) s, positions (T, N, 3) m at them, the document) of a morph-animated
    .glb, decoded here from its bytes: every accessor's layout, count and bounds checked."""
    doc, blob = parse_glb(path)
    node = doc["nodes"][0]
    mesh = doc["meshes"][node["mesh"]]
    (primitive,) = mesh["primitives"]
    sampler = doc["animations"][0]["samplers"][0]
    channel = doc["animations"][0]["channels"][0]
    assert channel["target"] == {"node": 0, "path": "weights"}
    for index, acc in enumerate(doc["accessors"]):
        if "min" in acc:
            values = accessor(doc, blob, index)
            assert acc["min"] == values.min(axis=0).tolist()
            assert acc["max"] == values.max(axis=0).tolist()
    base = dequantized(doc, blob, primitive["attributes"]["POSITION"])
    n, k = len(base), len(primitive["targets"])
    normals = dequantized(doc, blob, primitive["attributes"]["NORMAL"])
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6)
    indices = accessor(doc, blob, primitive["indices"])
    assert indices.max() < n and len(indices) % 3 == 0
    for t in primitive["targets"]:
        assert doc["accessors"][t["NORMAL"]]["count"] == n
    for index in [
        primitive["attributes"]["POSITION"],
        *(t["POSITION"] for t in primitive["targets"]),
    ]:
        assert doc["accessors"][index]["count"] == n and "min" in doc["accessors"][index]
    times = accessor(doc, blob, sampler["input"]).ravel()
    assert "min" in doc["accessors"][sampler["input"]] and np.all(np.diff(times) > 0)
    weights = accessor(doc, blob, sampler["output"]).reshape(len(times), k)
    assert len(mesh["weights"]) == k and mesh["extras"]["targetNames"] == [
        f"pc{i}" for i in range(k)
    ]
    targets = np.stack([dequantized(doc, blob, t["POSITION"]) for t in primitive["targets"]])
    scale = node.get("scale", [1.0, 1.0, 1.0])
    assert scale[0] == scale[1] == scale[2]
    positions = scale[0] * (base + np.einsum("tk,kni->tni", weights, targets))
    return times, positions, doc


@pytest.mark.parametrize("quantized", [True, False])
def test_the_file_decodes_to_the_animation_within_the_tolerance(
    tmp_path: Path, modes: MeshAnimation, quantized: bool
) -> None:
    morph = morph_animation(modes, 1e-6, 16, quantized)
    path = write_glb(morph, modes.faces, tmp_path / "fem.glb", "fem", {"fps": modes.fps})
    times, positions, doc = decoded_animation(path)
    np.testing.assert_allclose(times, modes.times, rtol=1e-6)
    assert len(morph.targets) == 3  # the animation's rank
    # float32 file: base + weights x targets is exact to a few float32 steps of the coordinates
    float32_steps = 4 * np.finfo(np.float32).eps * np.abs(modes.points).max()
    assert rms_distance(positions, modes.points) <= (1e-7 if quantized else float32_steps)
    assert doc["asset"]["version"] == "2.0" and doc["asset"]["extras"] == {"fps": 30.0}
    assert doc["extensionsRequired"] if quantized else "extensionsRequired" not in doc
    types = {doc["accessors"][t["POSITION"]]["componentType"] for t in doc["meshes"][0]
             ["primitives"][0]["targets"]}  # fmt: skip
    assert types == ({5122} if quantized else {5126})
    # every weight in [0, 1], the mesh's rest weights the first frame's
    weights = read_glb(path).weights
    assert weights.min() >= 0.0 and weights.max() <= 1.0
    np.testing.assert_array_equal(doc["meshes"][0]["weights"], weights[0])


def test_read_glb_gives_back_what_was_written(tmp_path: Path, modes: MeshAnimation) -> None:
    morph = morph_animation(modes, 1e-6, 16)
    back = read_glb(write_glb(morph, modes.faces, tmp_path / "fem.glb", "fem"))
    for name in ("targets", "normal_targets", "weights", "times", "base_normals"):
        np.testing.assert_array_equal(getattr(back, name), getattr(morph, name), err_msg=name)
    np.testing.assert_allclose(back.base, morph.base, rtol=0, atol=1e-8)  # in node units: 1 ulp
    assert (back.scale, back.quantized) == (morph.scale, True)


def test_the_fewest_targets_that_meet_the_tolerance(modes: MeshAnimation) -> None:
    assert len(morph_animation(modes, 1.0, 16).targets) == 1
    two = morph_animation(modes, 1e-6, 2)  # the limit wins over the tolerance
    assert len(two.targets) == 2 and rms_distance(two.positions(), modes.points) > 1e-6
    enough = rms_distance(two.positions(), modes.points) * 1.01
    assert len(morph_animation(modes, enough, 16).targets) == 2


def test_morphed_normals_follow_the_frames(modes: MeshAnimation) -> None:
    for quantized, degrees in ((False, 0.5), (True, 1.5)):
        normals = morph_animation(modes, 1e-6, 16, quantized).normals()
        angle = np.degrees(np.arccos(np.clip(np.sum(normals * modes.normals, -1), -1, 1)))
        assert angle.max() < degrees
    still = np.degrees(np.arccos(np.clip(np.sum(modes.normals[0] * modes.normals, -1), -1, 1)))
    assert still.max() > 5  # the frames' normals do turn


def test_a_still_animation_has_one_zero_target(tmp_path: Path) -> None:
    moving = three_modes(frames=1)
    still = MeshAnimation("still", np.repeat(moving.points, 4, axis=0), moving.faces, 30.0)
    morph = morph_animation(still, 1e-6, 8)
    assert len(morph.targets) == 1 and not morph.targets.any() and not morph.weights.any()
    _, positions, _ = decoded_animation(write_glb(morph, still.faces, tmp_path / "s.glb", "s"))
    np.testing.assert_allclose(positions, still.points, atol=1e-8)


def test_quantized_targets_take_half_the_room(tmp_path: Path, modes: MeshAnimation) -> None:
    sizes = {
        q: write_glb(morph_animation(modes, 1e-5, 16, q), modes.faces, tmp_path / f"{q}.glb", "m")
        .stat()
        .st_size
        for q in (True, False)
    }
    assert sizes[True] < 0.75 * sizes[False]


@pytest.mark.skipif(
    shutil.which("node") is None or not VALIDATOR.is_dir(),
    reason=f"no Khronos glTF validator (npm package gltf-validator) in {VALIDATOR}",
)
@pytest.mark.parametrize("quantized", [True, False])
def test_the_khronos_validator_finds_nothing(
    tmp_path: Path, modes: MeshAnimation, quantized: bool
) -> None:
    path = write_glb(morph_animation(modes, 1e-5, 16, quantized), modes.faces,
                     tmp_path / "fem.glb", "fem")  # fmt: skip
    script = (
        "const v = require(process.argv[1]);"
        "const data = new Uint8Array(require('fs').readFileSync(process.argv[2]));"
        "v.validateBytes(data).then(r => console.log(JSON.stringify(r)))"
        ".catch(e => { console.error(e); process.exit(2); });"
    )
    done = subprocess.run(
        ["node", "-e", script, str(VALIDATOR), str(path)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0, report
    info = report["info"]
    assert info["hasMorphTargets"] and info["animationCount"] == 1
    assert info["totalVertexCount"] == modes.vertices
    assert info["totalTriangleCount"] == len(modes.faces)


def test_a_long_take_compresses_to_under_a_tenth_of_the_usd(tmp_path: Path) -> None:
    take = three_modes(frames=90)
    usd = write_usd(take, tmp_path / "fem.usdc")
    glb = write_glb(morph_animation(take, 1e-4, 32), take.faces, tmp_path / "fem.glb", "fem")
    assert glb.stat().st_size <= 0.1 * usd.stat().st_size
