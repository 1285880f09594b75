"""A mesh animation as glTF 2.0 binary (.glb): a morph-target basis with animated weights.

The T frames become K morph targets, the first K principal components of the frames' vertex
positions, and K weights per frame, keyed at the frame times with linear interpolation. Each
target spans the whole range its component takes, so that every weight lies in [0, 1]: the
base shape is all weights 0. (Blender's importer clamps shape-key values to [0, 1] widened to
the first key's value only, io_scene_gltf2 4.4 and 5.0: other weights came out clamped.) K is
the smallest number that brings the decoded animation within a tolerance of the full one
(RMS over frames and vertices of the distance), up to a limit. Normals morph with the same
weights: the base normals unit, the targets' normal offsets a least-squares fit of the
frames' normals. Quantized (``KHR_mesh_quantization``, a required extension then) as gltfpack
does, the position offsets are 16-bit normalized integers in units of the node's scale (the
largest offset, m), the normal offsets 8-bit normalized integers (clipped to +-1: 0.1 % of
the demo FEM skin's, at folded vertices): about half the size of float targets.

pygltflib (maintained, on PyPI) models the glTF document; the binary layout is made here:
every buffer view 4-byte aligned, vertex attributes with an explicit byte stride (integer
VEC3 padded to 4 components), min / max of every POSITION and of the key times.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from physanim.export.animation import MeshAnimation

#: glTF constants: component types, buffer view targets, the quantization extension.
FLOAT, SHORT, BYTE, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5122, 5120, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
QUANTIZATION = "KHR_mesh_quantization"
#: Largest magnitude of the normalized integers of each component type.
NORMALIZED_MAX = {SHORT: 32767, BYTE: 127}
_DTYPES = {FLOAT: "<f4", SHORT: "<i2", BYTE: "i1", UNSIGNED_SHORT: "<u2", UNSIGNED_INT: "<u4"}
_WIDTH = {"SCALAR": 1, "VEC3": 3}


@dataclass(frozen=True)
class MorphAnimation:
    """An animation of N vertices as K morph targets and T frames of weights in [0, 1].

    ``base`` (N, 3) float32 m, ``base_normals`` (N, 3) float32 unit; ``targets`` (K, N, 3)
    float32 position offsets in m per unit weight, ``normal_targets`` (K, N, 3) float32
    normal offsets per unit weight; ``weights`` (T, K) float32 at ``times`` (T,) float32 s;
    ``quantized``: the targets lie on the normalized-integer grids, the position offsets on
    the int16 one in units of ``scale`` m (1 unquantized), the normal offsets on the int8 one.
    """

    base: NDArray
    base_normals: NDArray
    targets: NDArray
    normal_targets: NDArray
    weights: NDArray
    times: NDArray
    scale: float
    quantized: bool

    def positions(self) -> NDArray:
        """(T, N, 3) float32 m, the vertex positions at the key times: base + weights @
        targets."""
        k, n = self.targets.shape[:2]
        return self.base + (self.weights @ self.targets.reshape(k, -1)).reshape(-1, n, 3)

    def normals(self) -> NDArray:
        """(T, N, 3) float32 unit vertex normals at the key times (morphed, then renormalized
        as a renderer does)."""
        k, n = self.normal_targets.shape[:2]
        offsets = (self.weights @ self.normal_targets.reshape(k, -1)).reshape(-1, n, 3)
        return _unit(self.base_normals + offsets)


def _unit(v: NDArray) -> NDArray:
    """``v`` (..., 3) scaled to unit length along its last axis (zero vectors kept)."""
    norm = np.sqrt(np.einsum("...i,...i->...", v, v))[..., None]
    return v / np.where(norm > 0.0, norm, 1.0)


def rms_distance(a: NDArray, b: NDArray) -> float:
    """RMS over frames and vertices of the distance between (T, N, 3) positions, their unit
    (the squares summed in float64)."""
    d = np.asarray(a) - np.asarray(b)
    return float(np.sqrt(np.mean(np.einsum("tni,tni->tn", d, d), dtype=np.float64)))


def morph_animation(
    animation: MeshAnimation, tolerance_m: float, max_targets: int, quantized: bool = True
) -> MorphAnimation:
    """The principal-component morph basis of ``animation``: the fewest targets (1 at least,
    ``max_targets`` at most) whose decoded animation lies within ``tolerance_m`` m RMS of
    the frames (when ``max_targets`` cannot, those it allows). In float32: its rounding
    (~1e-8 m on a face) is far below any useful tolerance."""
    # products of T x 3N matrices: on one BLAS thread as fast, and no spinning against the
    # stages beside the export (two threads took 1 s for the demo's Gram matrix, one 0.04 s)
    with threadpool_limits(limits=1, user_api="blas"):
        return _morph_animation(animation, tolerance_m, max_targets, quantized)


def _morph_animation(
    animation: MeshAnimation, tolerance_m: float, max_targets: int, quantized: bool
) -> MorphAnimation:
    t, n = animation.frames, animation.vertices
    x = animation.points.reshape(t, -1)
    mean = x.mean(axis=0, dtype=np.float64).astype(np.float32)
    centred = x - mean
    gram = (centred @ centred.T).astype(np.float64)  # (T, T): T is far smaller than 3N
    energy, u = np.linalg.eigh(gram)
    order = np.argsort(energy)[::-1]
    energy, u = np.maximum(energy[order], 0.0), u[:, order]
    limit = max(1, min(max_targets, t))
    basis = u[:, :limit].astype(np.float32)
    singular = np.sqrt(energy[:limit]).astype(np.float32)
    inverse = np.divide(1.0, singular, out=np.zeros_like(singular), where=singular > 0.0)
    components = (basis.T @ centred) * inverse[:, None]  # (limit, 3N) unit rows
    coefficients = basis * singular  # (T, limit) m
    normals = animation.normals.reshape(t, -1)
    mean_normals = normals.mean(axis=0, dtype=np.float64).astype(np.float32)
    # the coefficients are orthogonal: each component's least-squares normal slope alone
    slopes = (basis.T @ (normals - mean_normals)) * inverse[:, None]  # (limit, 3N) per m
    # the residual RMS of k exact components, k = 0 .. T: where the search starts
    left = np.maximum(energy.sum() - np.r_[0.0, np.cumsum(energy)], 0.0)
    k = int(np.clip(np.argmax(np.sqrt(left / (t * n)) <= tolerance_m), 1, limit))
    while True:
        pca = (mean, components[:k], coefficients[:, :k])
        morph = _basis(*pca, mean_normals, slopes[:k], normals, animation.times, quantized)
        if k == limit or rms_distance(morph.positions(), animation.points) <= tolerance_m:
            return morph
        k += 1


def _basis(
    mean: NDArray,
    components: NDArray,
    coefficients: NDArray,
    mean_normals: NDArray,
    slopes: NDArray,
    normals: NDArray,
    times: NDArray,
    quantized: bool,
) -> MorphAnimation:
    """The morph animation of K principal ``components`` (K, 3N) unit, their
    ``coefficients`` (T, K) m about the ``mean`` (3N,) m, with weights in [0, 1]; normals
    from the frames' ``normals`` (T, 3N), their mean (3N,) and the components' ``slopes``
    (K, 3N) per m; quantized: the offsets rounded to their integer grids."""
    k, n = len(components), len(mean) // 3
    low = coefficients.min(axis=0)
    span = coefficients.max(axis=0) - low
    span = np.where(span > 0.0, span, 1.0)
    weights = (coefficients - low) / span
    base_normals = _unit((mean_normals + low @ slopes).reshape(n, 3))
    # least squares by the (K, T) pseudo-inverse: lstsq took 1 s for the 3N columns of the demo
    normal_targets = np.linalg.pinv(weights) @ (normals - base_normals.ravel())
    targets = span[:, None] * components
    scale = 1.0
    if quantized:  # in float64, as a reader dequantizes
        scale = float(np.abs(targets).max()) or 1.0
        steps = np.round(targets.astype(np.float64) / scale * NORMALIZED_MAX[SHORT])
        targets = steps / NORMALIZED_MAX[SHORT] * scale
        steps = np.round(
            np.clip(normal_targets.astype(np.float64), -1.0, 1.0) * NORMALIZED_MAX[BYTE]
        )
        normal_targets = steps / NORMALIZED_MAX[BYTE]
    return MorphAnimation(
        base=(mean + low @ components).reshape(n, 3).astype(np.float32),
        base_normals=base_normals.astype(np.float32),
        targets=targets.reshape(k, n, 3).astype(np.float32),
        normal_targets=normal_targets.reshape(k, n, 3).astype(np.float32),
        weights=weights.astype(np.float32),
        times=np.asarray(times, dtype=np.float32),
        scale=scale,
        quantized=quantized,
    )


class _Binary:
    """The binary chunk being laid out: buffer views, each 4-byte aligned, and accessors."""

    def __init__(self) -> None:
        import pygltflib

        self.g = pygltflib
        self.blob = bytearray()
        self.views: list[Any] = []
        self.accessors: list[Any] = []

    def add(
        self,
        data: NDArray,
        kind: str,
        component: int,
        *,
        target: int | None = None,
        normalized: bool = False,
        bounds: bool = False,
    ) -> int:
        """Accessor index of ``data`` (count, width) already in the dtype of ``component``,
        ``kind`` SCALAR or VEC3; a vertex attribute (``target`` ARRAY_BUFFER) gets an explicit
        stride, integer VEC3 padded to 4 components; ``bounds``: with min / max."""
        data = np.asarray(data, dtype=_DTYPES[component]).reshape(len(data), _WIDTH[kind])
        stride = None
        if target == ARRAY_BUFFER:
            pad = -data.shape[1] * data.itemsize % 4 // data.itemsize
            data = np.pad(data, ((0, 0), (0, pad)))
            stride = data.shape[1] * data.itemsize
        self.blob += bytes(-len(self.blob) % 4)
        offset = len(self.blob)
        self.blob += np.ascontiguousarray(data).tobytes()
        self.views.append(
            self.g.BufferView(
                buffer=0, byteOffset=offset, byteLength=len(self.blob) - offset,
                byteStride=stride, target=target,
            )
        )  # fmt: skip
        values = data[:, : _WIDTH[kind]]
        lo, hi = (values.min(axis=0).tolist(), values.max(axis=0).tolist()) if bounds else ([], [])
        self.accessors.append(
            self.g.Accessor(
                bufferView=len(self.views) - 1, componentType=component, count=len(data),
                type=kind, normalized=normalized or None, min=lo, max=hi,
            )
        )  # fmt: skip
        return len(self.accessors) - 1

    def offsets(self, values: NDArray, quantized: bool, component: int) -> int:
        """Accessor index of morph offsets (N, 3): float32, or on the normalized grid of
        ``component`` (quantized)."""
        if not quantized:
            return self.add(values, "VEC3", FLOAT, target=ARRAY_BUFFER, bounds=True)
        ints = np.round(values.astype(np.float64) * NORMALIZED_MAX[component])
        return self.add(ints, "VEC3", component, target=ARRAY_BUFFER, normalized=True, bounds=True)


def write_glb(
    morph: MorphAnimation,
    faces: NDArray,
    path: Path,
    name: str,
    extras: dict[str, Any] | None = None,
) -> Path:
    """Write ``morph`` on the triangles ``faces`` (F, 3) to ``path`` (.glb) and return it:
    one node (scaled by ``morph.scale``, its positions in units of it) and mesh called
    ``name`` (targets ``pc0``, ``pc1``...; its rest weights the first frame's), a
    double-sided skin-coloured material, and one animation of the node's weights keyed at
    ``morph.times``. ``extras``: JSON-able facts stored in ``asset.extras``."""
    import pygltflib as g

    out = _Binary()
    n = len(morph.base)
    index_type = UNSIGNED_SHORT if n < 2**16 - 1 else UNSIGNED_INT  # 65535: primitive restart
    indices = out.add(np.ravel(faces), "SCALAR", index_type, target=ELEMENT_ARRAY_BUFFER)
    scale = morph.scale  # the node's: positions in units of it
    position = out.add(morph.base / scale, "VEC3", FLOAT, target=ARRAY_BUFFER, bounds=True)
    normal = out.add(morph.base_normals, "VEC3", FLOAT, target=ARRAY_BUFFER)
    targets = [  # plain dicts: pygltflib reads targets back as such
        {"POSITION": out.offsets(p / scale, morph.quantized, SHORT),
         "NORMAL": out.offsets(q, morph.quantized, BYTE)}
        for p, q in zip(morph.targets, morph.normal_targets, strict=True)
    ]  # fmt: skip
    times = out.add(morph.times, "SCALAR", FLOAT, bounds=True)
    weights = out.add(morph.weights.ravel(), "SCALAR", FLOAT)
    out.blob += bytes(-len(out.blob) % 4)
    k = len(targets)
    gltf = g.GLTF2(
        asset=g.Asset(version="2.0", generator="physanim export", extras=extras or {}),
        extensionsUsed=[QUANTIZATION] if morph.quantized else [],
        extensionsRequired=[QUANTIZATION] if morph.quantized else [],
        scene=0,
        scenes=[g.Scene(nodes=[0])],
        nodes=[g.Node(name=name, mesh=0, scale=[scale] * 3 if scale != 1.0 else None)],
        meshes=[
            g.Mesh(
                name=name,
                primitives=[
                    g.Primitive(
                        attributes=g.Attributes(POSITION=position, NORMAL=normal),
                        indices=indices, material=0, targets=targets,
                    )
                ],
                weights=morph.weights[0].tolist(),
                extras={"targetNames": [f"pc{i}" for i in range(k)]},
            )
        ],
        materials=[
            g.Material(
                name="skin", doubleSided=True,
                pbrMetallicRoughness=g.PbrMetallicRoughness(
                    baseColorFactor=[0.8, 0.62, 0.54, 1.0], metallicFactor=0.0,
                    roughnessFactor=0.6,
                ),
            )
        ],
        animations=[
            g.Animation(
                name=name,
                samplers=[g.AnimationSampler(input=times, output=weights, interpolation="LINEAR")],
                channels=[
                    g.AnimationChannel(
                        sampler=0, target=g.AnimationChannelTarget(node=0, path="weights")
                    )
                ],
            )
        ],
        accessors=out.accessors,
        bufferViews=out.views,
        buffers=[g.Buffer(byteLength=len(out.blob))],
    )  # fmt: skip
    gltf.set_binary_blob(bytes(out.blob))
    path = Path(path)
    gltf.save_binary(str(path))
    return path


def read_glb(path: Path) -> MorphAnimation:
    """The morph animation of a .glb as :func:`write_glb` lays it out (one node, its mesh's
    primitive and one animation of its weights), in metres, targets dequantized."""
    import pygltflib

    gltf = pygltflib.GLTF2().load_binary(str(path))
    blob = gltf.binary_blob()

    def read(index: int) -> NDArray:
        acc = gltf.accessors[index]
        view = gltf.bufferViews[acc.bufferView]
        dtype = np.dtype(_DTYPES[acc.componentType])
        width = _WIDTH[acc.type]
        stride = view.byteStride or width * dtype.itemsize
        data = np.ndarray(
            (acc.count, width), dtype, blob, view.byteOffset + (acc.byteOffset or 0),
            (stride, dtype.itemsize),
        ).astype(np.float64)  # fmt: skip
        if acc.normalized:
            data = np.maximum(data / NORMALIZED_MAX[acc.componentType], -1.0)
        return data

    scale = (gltf.nodes[0].scale or [1.0])[0]
    primitive = gltf.meshes[gltf.nodes[0].mesh].primitives[0]
    sampler = gltf.animations[0].samplers[0]
    times = read(sampler.input).ravel()
    targets = primitive.targets
    return MorphAnimation(
        base=(read(primitive.attributes.POSITION) * scale).astype(np.float32),
        base_normals=read(primitive.attributes.NORMAL).astype(np.float32),
        targets=np.stack([read(t["POSITION"]) * scale for t in targets]).astype(np.float32),
        normal_targets=np.stack([read(t["NORMAL"]) for t in targets]).astype(np.float32),
        weights=read(sampler.output).reshape(len(times), len(targets)).astype(np.float32),
        times=times.astype(np.float32),
        scale=scale,
        quantized=QUANTIZATION in (gltf.extensionsRequired or []),
    )
