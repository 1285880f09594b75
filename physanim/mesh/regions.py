"""Facial material regions (seed 004: Cheek, cphs(L), cphs(R), Cheilion, cphi, Alare, default).

A skin point belongs to a region when it lies within that region's radius of one of the
region's feature points (:data:`REGION_LANDMARKS`); where radii overlap the nearest feature point
wins; everything else is the default region. Tets take the region of the nearest skin point.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from physanim.mesh.params import REGION_LANDMARKS, REGION_NAMES, MaterialsParams
from physanim.mesh.topology import triangle_areas

#: Label of the default region; region ``REGION_NAMES[i]`` has label ``i + 1``.
DEFAULT_LABEL = 0
LABEL_NAMES: tuple[str, ...] = ("default", *REGION_NAMES)


def skin_regions(
    points: np.ndarray, landmarks: dict[str, np.ndarray], params: MaterialsParams
) -> np.ndarray:
    """Region label (N,) int8 of skin points (N, 3) in metres (0 = default, i+1 = REGION_NAMES[i]).

    Args:
        points: (N, 3) skin vertices (or skin nodes), metres.
        landmarks: feature-point name -> (3,) position on the skin, metres; needs every name in
            :data:`REGION_LANDMARKS`.
        params: region radii.
    """
    seeds, labels, radii = [], [], []
    for i, region in enumerate(REGION_NAMES):
        for name in REGION_LANDMARKS[region]:
            if name not in landmarks:
                raise ValueError(f"landmarks lack '{name}', needed for material region '{region}'")
            seeds.append(np.asarray(landmarks[name], dtype=np.float64))
            labels.append(i + 1)
            radii.append(params.radius(region))
    p = np.asarray(points, dtype=np.float64)
    d = np.linalg.norm(p[:, None, :] - np.asarray(seeds)[None], axis=2)  # (N, seeds)
    d = np.where(d <= np.asarray(radii)[None], d, np.inf)
    nearest = np.argmin(d, axis=1)
    inside = np.isfinite(d[np.arange(len(p)), nearest])
    return np.where(inside, np.asarray(labels)[nearest], DEFAULT_LABEL).astype(np.int8)


def tet_regions(
    nodes: np.ndarray,
    tets: np.ndarray,
    skin_points: np.ndarray,
    skin_labels: np.ndarray,
) -> np.ndarray:
    """Region label (m,) int8 of tets (m, 4): the label of the skin point nearest the centroid.

    Args:
        nodes: (n, 3) tet nodes, metres; tets: (m, 4) int.
        skin_points: (S, 3) labelled skin points, metres; skin_labels: (S,) their labels.
    """
    centroids = np.asarray(nodes)[np.asarray(tets)].mean(axis=1)
    _, j = cKDTree(np.asarray(skin_points)).query(centroids)
    return np.asarray(skin_labels, dtype=np.int8)[j]


def region_areas(vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Skin area (len(LABEL_NAMES),) per region label in m^2; a triangle's area is split
    equally among its three vertices' labels."""
    a = triangle_areas(vertices, faces) / 3.0
    lab = np.asarray(labels)[np.asarray(faces)]
    return np.bincount(lab.ravel(), weights=np.repeat(a, 3), minlength=len(LABEL_NAMES))


def plot_regions(
    vertices: np.ndarray,
    faces: np.ndarray,
    labels: np.ndarray,
    path: Path | str,
    landmarks: dict[str, np.ndarray] | None = None,
) -> Path:
    """Write a front-view PNG of the skin coloured by region (actor frame: x left, y up).

    Args:
        vertices: (N, 3) skin, metres; faces: (M, 3); labels: (N,) region labels.
        path: output PNG path.
        landmarks: optional feature points to mark, name -> (3,) metres.

    Returns:
        The written path.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Patch

    v = np.asarray(vertices)
    f = np.asarray(faces)
    lab = np.asarray(labels)[f]
    face_label = np.where((lab[:, 0] == lab[:, 1]) | (lab[:, 0] == lab[:, 2]), lab[:, 0], lab[:, 1])
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    shade = 0.45 + 0.55 * np.clip(fn[:, 2] / np.maximum(np.linalg.norm(fn, axis=1), 1e-30), 0, 1)
    colours = np.array(plt.get_cmap("tab10")(np.arange(len(LABEL_NAMES))))
    colours[0, :3] = 0.85
    rgba = colours[face_label] * np.c_[shade, shade, shade, np.ones_like(shade)]

    fig, ax = plt.subplots(figsize=(6, 7), dpi=110)
    # Seen from the front (+z), +x (the actor's left) is to the viewer's right; paint back to
    # front (increasing z) so nearer triangles cover farther ones.
    order = np.argsort(v[f].mean(axis=1)[:, 2])
    xy = v[:, :2][f[order]] * 1e3
    ax.add_collection(PolyCollection(xy, facecolors=rgba[order], edgecolors="none"))
    ax.autoscale_view()
    if landmarks:
        for name, p in landmarks.items():
            ax.plot(p[0] * 1e3, p[1] * 1e3, "k.", ms=4)
            ax.annotate(
                name,
                (p[0] * 1e3, p[1] * 1e3),
                fontsize=6,
                xytext=(2, 2),
                textcoords="offset points",
            )
    ax.legend(
        handles=[Patch(color=colours[i], label=n) for i, n in enumerate(LABEL_NAMES)],
        loc="upper right",
        fontsize=7,
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm): actor's right <-  -> actor's left")
    ax.set_ylabel("y (mm)")
    ax.set_title("Material regions (front view)")
    path = Path(path)
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path
