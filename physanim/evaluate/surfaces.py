"""Is a moved scan a clean surface? Its silhouette against the truth's, and how far any of its
triangles is stretched or turned over.

The panel shows the scan moved by the captured motion and by the FEM. A tear, a flap or a
fold in those renders is seen at once, but the motion fidelity (a mean over the skin) hardly
sees it. Two measures do:

- **silhouette agreement**: the scan moved by the model and the same scan moved by the truth
  (each vertex following the true surface point it lies on at the first frame), rasterised by
  the same camera (the panel's frontal framing, turned about the vertical by each view's
  azimuth), each filled to its outline; intersection over union of the two per frame and view
  (1: the outlines agree). A flap or a gap along the border shows as a loss of a few per cent.
  The outline, not the covered pixels: the scan's topology is fixed, so its only openings are
  its own holes and the mouth, which the lip seam lets open where a truth without a mouth
  opening (the demo's: lips that stretch as one sheet) keeps it shut. Counting the open mouth
  as a loss cost the demo's FEM 0.8 % of its frontal overlap at the jaw drop, an artefact of
  the truth; a tear cannot open inside a fixed-topology mesh, it shows as stretch;
- **triangle stretch**: per scan triangle, the largest singular value of its deformation
  gradient from the first frame (the rest shape; 1: unstretched) and whether its normal has
  turned over; triangles touching the lip seam (where the cut lets the lips part) are left
  out, and slivers (shape quality below :data:`MIN_QUALITY`; 8 of the demo scan's 55k), whose
  stretch is ill-conditioned: a 0.01 mm high sliver moved 0.2 mm out of line reads 40.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import binary_fill_holes

from physanim.cameras import Camera, frontal_camera, intrinsics, turntable, view_matrix
from physanim.capture.raster import rasterize

#: Triangles of a lower shape quality (1: equilateral; 0: flat) are left out of the stretch.
MIN_QUALITY = 0.05


def triangle_quality(vertices: NDArray, faces: NDArray) -> NDArray:
    """(F,) shape quality 4 sqrt(3) area / (sum of the squared edge lengths): 1 for an
    equilateral triangle, 0 for a flat one, of ``faces`` (F, 3) at ``vertices`` (N, 3)."""
    t = vertices[faces]
    edges = t - np.roll(t, 1, axis=1)
    area = 0.5 * np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1)
    return 4.0 * np.sqrt(3.0) * area / np.maximum((edges**2).sum(axis=(1, 2)), 1e-300)


@dataclass(frozen=True)
class SurfaceQuality:
    """Of one moved scan over T frames and V views: ``silhouette_iou`` (T, V) against the
    truth's silhouette; ``max_stretch`` (T,) the largest principal stretch of any triangle
    outside the lip seam; ``inverted`` (T,) int how many of them have turned over."""

    silhouette_iou: NDArray
    max_stretch: NDArray
    inverted: NDArray


def view_cameras(vertices: NDArray, size: tuple[int, int], views_deg: tuple[float, ...]) -> list:
    """The cameras of the silhouettes: the frontal framing of ``vertices`` (N, 3) m for
    ``size`` (W, H) pixels, turned by each azimuth of ``views_deg`` (towards the actor's left)."""
    front = frontal_camera(vertices, size)
    return [turntable(front, az) for az in views_deg]


def silhouette(points: NDArray, faces: NDArray, camera: Camera, size: tuple[int, int]) -> NDArray:
    """(H, W) bool: the outline of the mesh ``points`` (N, 3) m / ``faces`` (F, 3) seen by
    ``camera`` at ``size`` (W, H) pixels: the pixels it covers and those it encloses."""
    view = view_matrix(camera)
    cam_pts = points @ view[:, :3].T + view[:, 3]
    covered = rasterize(cam_pts, faces, intrinsics(camera, size), size[::-1], near=1e-3).mask
    return binary_fill_holes(covered)


def silhouettes(
    frames: NDArray, faces: NDArray, cameras: list, size: tuple[int, int], workers: int = 2
) -> NDArray:
    """(T, V, H, W) bool silhouettes of ``frames`` (T, N, 3) m by each of the V ``cameras``."""
    with ThreadPoolExecutor(workers) as pool:  # the z-buffer releases the GIL
        return np.asarray(
            list(pool.map(lambda f: [silhouette(f, faces, c, size) for c in cameras], frames))
        )


def iou(a: NDArray, b: NDArray) -> NDArray:
    """Intersection over union of boolean masks (..., H, W) over their last two axes."""
    inter = (a & b).sum(axis=(-2, -1))
    union = (a | b).sum(axis=(-2, -1))
    return np.where(union > 0, inter / np.maximum(union, 1), 1.0)


@dataclass(frozen=True)
class RestTriangles:
    """Triangles ``faces`` (F, 3) in their rest shape, in their own plane: edge 1 = (a, 0),
    edge 2 = (b, c) (F,) m each; ``normal`` (F, 3) their unnormalised rest normals."""

    faces: NDArray
    a: NDArray
    b: NDArray
    c: NDArray
    normal: NDArray

    @classmethod
    def of(cls, rest: NDArray, faces: NDArray) -> RestTriangles:
        """The triangles ``faces`` (F, 3) of the rest positions ``rest`` (N, 3) m."""
        r = rest[faces]
        e1, e2 = r[:, 1] - r[:, 0], r[:, 2] - r[:, 0]
        normal = np.cross(e1, e2)
        a = np.linalg.norm(e1, axis=1)
        return cls(faces, a, (e1 * e2).sum(axis=1) / a, np.linalg.norm(normal, axis=1) / a, normal)

    def stretch(self, moved: NDArray) -> tuple[NDArray, NDArray]:
        """Largest principal stretch (F,) of each triangle moved to ``moved`` (N, 3) m (1:
        unstretched), and (F,) bool whether its normal turned over."""
        p = moved[self.faces]
        d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        # columns of the deformation gradient [d1 d2] [[a, b], [0, c]]^-1 (3 x 2 each)
        g1 = d1 / self.a[:, None]
        g2 = (d2 - (self.b / self.a)[:, None] * d1) / self.c[:, None]
        c11, c22, c12 = (g1 * g1).sum(axis=1), (g2 * g2).sum(axis=1), (g1 * g2).sum(axis=1)
        half_trace = 0.5 * (c11 + c22)  # right Cauchy-Green tensor [[c11, c12], [c12, c22]]
        largest = half_trace + np.hypot(0.5 * (c11 - c22), c12)  # no cancellation
        turned = (np.cross(d1, d2) * self.normal).sum(axis=1) < 0.0
        return np.sqrt(largest), turned


def seam_faces(faces: NDArray, parent: NDArray) -> NDArray:
    """(F,) bool: the triangles touching the lip seam (a vertex the cut duplicated: one of
    several scan vertices with the same ``parent`` (N,))."""
    on_seam = np.bincount(parent)[parent] > 1
    return on_seam[faces].any(axis=1)


def surface_quality(
    frames: NDArray,
    truth_masks: NDArray,
    faces: NDArray,
    away_from_seam: NDArray,
    cameras: list,
    size: tuple[int, int],
    workers: int = 2,
) -> SurfaceQuality:
    """The quality of the scan moved to ``frames`` (T, N, 3) m (the first: its rest shape)
    against the truth's silhouettes ``truth_masks`` (T, V, H, W) by the same ``cameras``;
    stretch over the triangles ``faces[away_from_seam]`` that are not slivers."""
    counted = away_from_seam & (triangle_quality(frames[0], faces) >= MIN_QUALITY)
    rest = RestTriangles.of(frames[0], faces[counted])

    def one(t: int) -> tuple[NDArray, float, int]:
        masks = np.asarray([silhouette(frames[t], faces, c, size) for c in cameras])
        stretch, turned = rest.stretch(frames[t])
        return iou(masks, truth_masks[t]), float(stretch.max()), int(turned.sum())

    with ThreadPoolExecutor(workers) as pool:  # the z-buffer and numpy release the GIL
        found = list(pool.map(one, range(len(frames))))
    overlap, largest, turned = zip(*found, strict=True)
    return SurfaceQuality(np.asarray(overlap), np.asarray(largest), np.asarray(turned))
