"""Build the project's CANDIDE-style face model procedurally and write ``data/model.npz``.

Run ``python -m physanim.face.build_model`` to rebuild (deterministic, ~10 s).

How the model is made:
1. **Layout.** ``LAYOUT_MM`` is a hand-designed, bilaterally symmetric 2D layout in the
   actor frame's x-y plane (mm, origin at the pronasale): every vertex is named; the left half
   (+x, suffix ``_L``) is listed and mirrored to ``_R``. The positions were read off a
   frontal rendering of the demo actor (``physanim.capture.actor.build_actor``: pymeshlab's
   face000 scan in the actor frame) and symmetrised, so the wireframe's features sit on the
   actor's eyes, nose, lips, brows, cheeks and chin.
2. **Depth.** Each vertex takes the z of the scan's front-most surface at its (x, y), by ray
   casting along -z (Open3D); points over a scan hole take the front-most z among the
   nearest scan vertices in x-y.
3. **Triangles.** Delaunay triangulation of the layout; triangles inside the eye openings
   and the mouth slit (between the inner upper and inner lower lip vertices, 1 mm apart) are
   removed so eyelids can close and lips can part.
4. **Units.** Shape Units and FACS Action Units are displacement fields (m per unit) built
   from smooth Gaussian weights of the symmetric layout position (so an ``_L`` unit is the
   exact mirror image of its ``_R`` twin) times fixed directions; the jaw drop is a rotation
   about a jaw axis behind the face. Amplitudes at unit value are given in ``_action_units``
   and ``_shape_units``.
"""

from __future__ import annotations

import numpy as np
import open3d as o3d
from matplotlib.path import Path as PolygonPath
from scipy.spatial import Delaunay, cKDTree
from scipy.spatial.transform import Rotation

from physanim.face.landmarks import FEATURE_POINTS, mirror_name
from physanim.face.model import MODEL_PATH, MOUTH_SLIT, FaceModel, save_face_model

MM = 1e-3

#: Midline vertices: name -> (x, y) mm.
MIDLINE_MM: dict[str, tuple[float, float]] = {
    "forehead_top": (0.0, 70.0),
    "forehead": (0.0, 58.0),
    "glabella": (0.0, 47.0),
    "nasion": (0.0, 38.0),
    "dorsum_upper": (0.0, 26.0),
    "dorsum_lower": (0.0, 13.0),
    "pronasale": (0.0, 0.0),
    "subnasale": (0.0, -6.0),
    "labrale_superius": (0.0, -15.5),
    "stomion_superius": (0.0, -17.8),
    "stomion_inferius": (0.0, -18.8),
    "labrale_inferius": (0.0, -23.5),
    "labiomental": (0.0, -28.0),
    "pogonion": (0.0, -34.0),
}

#: Left-half vertices (actor's left, +x): base name -> (x, y) mm; mirrored to ``_R``.
LEFT_MM: dict[str, tuple[float, float]] = {
    "forehead_1": (15.0, 70.0),
    "forehead_2": (30.0, 66.0),
    "forehead_3": (42.0, 58.0),
    "forehead_4": (15.0, 59.0),
    "forehead_5": (29.0, 58.0),
    "brow_inner": (10.0, 50.0),
    "brow_mid": (20.0, 53.0),
    "brow_outer": (31.0, 49.0),
    "temple": (42.0, 46.0),
    "en": (9.0, 37.0),
    "lid_upper_1": (14.0, 41.0),
    "lid_upper_2": (20.0, 43.0),
    "lid_upper_3": (26.0, 43.0),
    "ex": (31.0, 39.5),
    "lid_lower_3": (26.0, 33.5),
    "pi": (19.5, 31.5),
    "lid_lower_1": (13.0, 33.0),
    "nose_side_1": (6.0, 25.0),
    "nose_side_2": (8.0, 12.0),
    "al": (16.5, 2.0),
    "nostril": (6.0, -3.0),
    "infraorbital_1": (12.0, 24.0),
    "infraorbital_2": (21.0, 22.0),
    "infraorbital_3": (31.0, 25.0),
    "zygoma": (41.0, 31.0),
    "cheek_medial": (18.0, 12.0),
    "cheek_upper": (28.0, 14.0),
    "cheek": (30.0, 2.0),
    "cheek_lateral": (40.0, 17.0),
    "cheek_low": (38.0, -4.0),
    "nasolabial_1": (22.0, -6.0),
    "nasolabial_2": (27.0, -13.0),
    "cphs": (3.5, -11.0),
    "cphi": (4.0, -15.5),
    "lip_upper_1": (10.0, -16.0),
    "lip_upper_2": (15.0, -17.0),
    "lip_upper_in_1": (6.0, -17.8),
    "lip_upper_in_2": (12.0, -18.0),
    "ch": (19.0, -18.3),
    "lip_lower_in_1": (6.0, -18.8),
    "lip_lower_in_2": (12.0, -19.0),
    "lip_lower_1": (7.0, -23.5),
    "lip_lower_2": (14.0, -22.5),
    "mouth_lateral": (26.0, -21.0),
    "jaw_1": (36.0, -10.0),
    "jaw_2": (32.0, -23.0),
    "jaw_3": (26.0, -32.0),
    "chin_1": (10.0, -30.0),
    "chin_2": (20.0, -29.0),
    "chin_3": (13.0, -37.0),
    "face_edge": (44.0, 6.0),
}

EYE_RING = (
    "en", "lid_upper_1", "lid_upper_2", "lid_upper_3", "ex", "lid_lower_3", "pi", "lid_lower_1"
)  # fmt: skip
UPPER_LIP = {"labrale_superius", "stomion_superius", "cphs", "cphi"} | {
    "lip_upper_1", "lip_upper_2", "lip_upper_in_1", "lip_upper_in_2"
}  # fmt: skip
LOWER_LIP = {"stomion_inferius", "labrale_inferius", "lip_lower_1", "lip_lower_2"} | {
    "lip_lower_in_1", "lip_lower_in_2"
}  # fmt: skip
#: Upper lid vertex -> the lower lid vertex it closes onto (eye closure).
LID_PAIRS = {"lid_upper_1": "lid_lower_1", "lid_upper_2": "pi", "lid_upper_3": "lid_lower_3"}


def layout() -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    """Vertex names (V,), symmetric layout (V, 2) mm and mirror indices (V,) of the design."""
    names = list(MIDLINE_MM)
    xy = list(MIDLINE_MM.values())
    for side, sign in (("_L", 1.0), ("_R", -1.0)):
        names += [n + side for n in LEFT_MM]
        xy += [(sign * x, y) for x, y in LEFT_MM.values()]
    index = {n: i for i, n in enumerate(names)}
    mirror = np.array([index[mirror_name(n)] for n in names], dtype=np.int64)
    return tuple(names), np.array(xy, dtype=np.float64), mirror


def _base(name: str) -> str:
    return name[:-2] if name.endswith(("_L", "_R")) else name


def triangulate(names: tuple[str, ...], xy: np.ndarray) -> np.ndarray:
    """Delaunay triangles (F, 3) of the layout (V, 2), minus eye openings and the mouth slit.

    The connectivity is computed with the mouth opened (everything below the mouth corners
    moved 4 mm down) so that no triangle bridges the 1 mm lip slit.
    """
    index = {n: i for i, n in enumerate(names)}
    y_ch = xy[index["ch_L"], 1]
    opened = xy.copy()
    opened[xy[:, 1] < y_ch - 0.1, 1] -= 4.0
    tri = Delaunay(opened).simplices
    holes = [[index[n + s] for n in EYE_RING] for s in ("_L", "_R")]
    mouth = [u for u, _ in MOUTH_SLIT] + [lo for _, lo in reversed(MOUTH_SLIT[1:-1])]
    holes.append([index[n] for n in mouth])
    centroids = opened[tri].mean(axis=1)
    inside = np.zeros(len(tri), dtype=bool)
    for ring in holes:
        inside |= PolygonPath(opened[ring]).contains_points(centroids)
    tri = tri[~inside]
    a, b, c = (xy[tri[:, k]] for k in range(3))
    ab, ac = b - a, c - a
    ccw = ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0] > 0
    tri[~ccw] = tri[~ccw][:, [0, 2, 1]]
    return tri.astype(np.int64)


def surface_depth(
    xy_m: np.ndarray, scan_vertices: np.ndarray, scan_faces: np.ndarray
) -> np.ndarray:
    """z (K,) m of the scan's front-most surface at points ``xy_m`` (K, 2) m (actor frame)."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(scan_vertices.astype(np.float32)),
        o3d.core.Tensor(scan_faces.astype(np.uint32)),
    )
    top = scan_vertices[:, 2].max() + 0.1
    rays = np.zeros((len(xy_m), 6), dtype=np.float32)
    rays[:, :2] = xy_m
    rays[:, 2] = top
    rays[:, 5] = -1.0
    t_hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
    z = top - t_hit
    miss = ~np.isfinite(t_hit)
    if miss.any():
        _, nn = cKDTree(scan_vertices[:, :2]).query(xy_m[miss], k=16)
        z[miss] = scan_vertices[nn, 2].max(axis=1)
    return z


def _gauss(xy: np.ndarray, centre: tuple[float, float], radius: tuple[float, float]) -> np.ndarray:
    """Anisotropic Gaussian weight (V,) of layout points (V, 2) mm; radii (rx, ry) mm."""
    d = (xy - np.asarray(centre)) / np.asarray(radius)
    return np.exp(-0.5 * (d**2).sum(axis=1))


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _sided(xy: np.ndarray, centre, radius, direction_mm) -> dict[str, np.ndarray]:
    """``{'L': field, 'R': field}`` (V, 3) mm: a Gaussian bump on each side, mirrored in x."""
    out = {}
    for side, s in (("L", 1.0), ("R", -1.0)):
        w = _gauss(xy, (s * centre[0], centre[1]), radius)
        d = np.array([s * direction_mm[0], direction_mm[1], direction_mm[2]])
        out[side] = w[:, None] * d
    return out


def _action_units(
    names: tuple[str, ...], xy: np.ndarray, vertices_mm: np.ndarray
) -> dict[str, np.ndarray]:
    """FACS Action Unit fields (V, 3) in mm at activation 1 (see inline amplitudes)."""
    base = np.array([_base(n) for n in names])
    upper = np.isin(base, list(UPPER_LIP))
    lower = np.isin(base, list(LOWER_LIP))
    is_ch = base == "ch"
    aus: dict[str, np.ndarray] = {}

    # AU26/27 jaw drop: 14 deg rotation about a jaw axis 85 mm behind, 5 mm above the nose tip;
    # lower lip and chin follow fully, upper lip not at all, cheeks blend in with height.
    w = _smoothstep((-13.0 - xy[:, 1]) / 14.0)
    w[lower] = 1.0
    w[upper] = 0.0
    w[is_ch] = 0.5
    pivot = np.array([0.0, 5.0, -85.0])
    rot = Rotation.from_euler("x", 14.0, degrees=True).as_matrix()
    rel = vertices_mm - pivot
    aus["jaw_drop"] = w[:, None] * (rel @ rot.T - rel)

    # AU25 lips part: inner lips open 3 mm each, fading over the lips.
    part = np.zeros_like(vertices_mm)
    mouth_w = _gauss(xy, (0.0, -18.3), (14.0, 8.0))
    part[upper, 1] = 3.0 * mouth_w[upper]
    part[lower, 1] = -3.0 * mouth_w[lower]
    aus["lips_part"] = part

    # Mouth-corner units: Gaussian about the cheilion (the smile also lifts the cheek: wider).
    ch = LEFT_MM["ch"]
    for name, direction, radius in (
        ("lip_corner_puller", (4.5, 5.0, -2.0), 12.0),  # AU12 smile: out, up, back
        ("lip_stretcher", (6.0, -1.0, -1.5), 8.0),  # AU20
        ("lip_corner_depressor", (1.0, -5.0, 0.0), 8.0),  # AU15
    ):
        for side, field in _sided(xy, ch, (radius, radius), direction).items():
            aus[f"{name}_{side}"] = field

    # AU10 upper lip raiser: upper lip and nasolabial area up 3.5 mm, forward 1 mm.
    w = _gauss(xy, (0.0, -13.0), (14.0, 6.0))
    w[lower | (xy[:, 1] < -18.3)] = 0.0
    aus["upper_lip_raiser"] = w[:, None] * np.array([0.0, 3.5, 1.0])

    # Brows: AU1 inner / AU2 outer brow raiser 5 mm up; AU4 lowerer 4 mm down, 2.5 mm inward.
    for name, centre in (("inner_brow_raiser", (10.0, 50.0)), ("outer_brow_raiser", (31.0, 49.0))):
        for side, field in _sided(xy, centre, (8.0, 8.0), (0.0, 5.0, 0.0)).items():
            aus[f"{name}_{side}"] = field
    low = _sided(xy, (10.0, 50.0), (9.0, 9.0), (-2.5, -4.0, 0.0))
    aus["brow_lowerer"] = low["L"] + low["R"]

    # AU43 eye closure: each upper-lid vertex moves down onto its lower-lid partner (1 mm gap);
    # the brow row follows by 10 %.
    index = {n: i for i, n in enumerate(names)}
    for side in ("L", "R"):
        field = np.zeros_like(vertices_mm)
        for up, lo in LID_PAIRS.items():
            i, j = index[f"{up}_{side}"], index[f"{lo}_{side}"]
            field[i, 1] = xy[j, 1] - xy[i, 1] + 1.0
        for n in ("brow_inner", "brow_mid", "brow_outer"):
            field[index[f"{n}_{side}"], 1] = -1.0
        aus[f"eye_closure_{side}"] = field
    return aus


def _shape_units(
    names: tuple[str, ...], xy: np.ndarray, vertices_mm: np.ndarray
) -> dict[str, np.ndarray]:
    """Shape Unit fields (V, 3) in mm per unit (amplitudes inline)."""
    v = vertices_mm
    zero = np.zeros(len(v))
    sus = {
        "face_width": np.stack([0.1 * v[:, 0], zero, zero], axis=1),  # +10 % width
        "face_height": np.stack([zero, 0.1 * v[:, 1], zero], axis=1),  # +10 % height
        "face_depth": np.stack([zero, zero, 0.1 * v[:, 2]], axis=1),  # +10 % depth
    }
    nose = _gauss(xy, (0.0, 8.0), (9.0, 14.0))
    sus["nose_protrusion"] = nose[:, None] * np.array([0.0, 0.0, 4.0])  # 4 mm
    wide = _gauss(xy, (0.0, 2.0), (12.0, 8.0))
    sus["nose_width"] = np.stack([0.25 * v[:, 0] * wide, zero, zero], axis=1)  # +25 %
    mouth = _gauss(xy, (0.0, -18.3), (16.0, 7.0))
    sus["mouth_width"] = np.stack([0.15 * v[:, 0] * mouth, zero, zero], axis=1)  # +15 %
    sus["mouth_vertical"] = mouth[:, None] * np.array([0.0, 3.0, 0.0])  # 3 mm up
    eyes = _sided(xy, (20.0, 38.0), (10.0, 8.0), (2.5, 0.0, 0.0))
    sus["eye_separation"] = eyes["L"] + eyes["R"]  # 2.5 mm apart each
    up = _sided(xy, (20.0, 38.0), (10.0, 8.0), (0.0, 2.5, 0.0))
    sus["eye_vertical"] = up["L"] + up["R"]  # 2.5 mm up
    brow = _sided(xy, (20.0, 51.0), (12.0, 5.0), (0.0, 3.0, 0.0))
    sus["brow_vertical"] = brow["L"] + brow["R"]  # 3 mm up
    chin = _smoothstep((-20.0 - xy[:, 1]) / 14.0)
    sus["chin_height"] = chin[:, None] * np.array([0.0, -4.0, 0.0])  # 4 mm longer
    return sus


def build_face_model(scan_vertices: np.ndarray, scan_faces: np.ndarray) -> FaceModel:
    """Build the model on a neutral face scan (N, 3) m / (M, 3) already in the actor frame."""
    names, xy_mm, mirror = layout()
    missing = [n for n in FEATURE_POINTS if n not in names]
    if missing:
        raise ValueError(f"LAYOUT_MM lacks feature points {missing}")
    xy = xy_mm * MM
    z = surface_depth(xy, scan_vertices, scan_faces)
    vertices = np.column_stack([xy, z - z[names.index("pronasale")]])
    vertices_mm = vertices / MM
    aus = _action_units(names, xy_mm, vertices_mm)
    sus = _shape_units(names, xy_mm, vertices_mm)
    return FaceModel(
        vertices=vertices,
        triangles=triangulate(names, xy_mm),
        vertex_names=names,
        mirror=mirror,
        layout=xy,
        su=np.stack(list(sus.values())) * MM,
        au=np.stack(list(aus.values())) * MM,
        su_names=tuple(sus),
        au_names=tuple(aus),
    )


def main() -> None:
    """Build the model on the demo actor and write it to ``MODEL_PATH``."""
    from physanim.capture.actor import build_actor

    actor = build_actor()
    model = build_face_model(actor.vertices, actor.faces)
    save_face_model(model, MODEL_PATH)
    print(
        f"{MODEL_PATH}: {model.n_vertices} vertices, {len(model.triangles)} triangles, "
        f"{len(model.su_names)} SUs, {len(model.au_names)} AUs"
    )


if __name__ == "__main__":
    main()
