"""The project's own backend of the face renders: its compiled z-buffer rasteriser
(``physanim.capture.raster``) and a compiled per-pixel shader that lights the skin as the VTK
backend does (VTK's light kit, Phong reflection, two-sided); no OpenGL at all.

Why not VTK alone: without a GPU, VTK draws through Mesa's llvmpipe, whose cost grows with the
triangles (a 166k-triangle scan at 480 x 640: 32 ms a view on one core, 47 ms with the upload
and the read-back), while the face covers fewer pixels than it has triangles. Rasterising them
here takes 3 ms and shading the covered pixels 2 ms. The VTK backend stays as the reference
this one is tested against (``tests/render/test_face.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from physanim.cameras import Camera, intrinsics, view_matrix
from physanim.capture.raster import rasterize
from physanim.render.colours import BACKGROUND

#: The light kit pyvista gives every VTK renderer (vtkLightKit's defaults: a warm key light
#: of intensity 0.75 at elevation 50 and azimuth 10 degrees, a cool fill light of a third of
#: it at -75 / -10, two back lights of 0.75 / 3.5 at +-110 degrees, a headlight of a third),
#: as directions towards each light in the OpenCV camera frame (+x right, +y down, +z
#: forward; VTK's camera frame with y and z negated) and intensity times colour.
LIGHT_DIRECTIONS = np.array([
    [0.0, 0.0, -1.0],  # headlight
    [0.1116, -0.766, -0.633],  # key
    [-0.0449, 0.9659, -0.2549],  # fill
    [0.9397, 0.0, 0.342],  # back, right
    [-0.9397, 0.0, 0.342],  # back, left
])  # fmt: skip
LIGHT_COLOURS = np.array([
    0.25 * np.array([1.0, 1.0, 1.0]),
    0.75 * np.array([1.0, 0.9725, 0.902]),
    0.25 * np.array([0.9098, 0.9333, 1.0]),
    0.2143 * np.array([1.0, 1.0, 1.0]),
    0.2143 * np.array([1.0, 1.0, 1.0]),
])  # fmt: skip
#: The skin's reflection: ambient, diffuse and specular coefficients and the specular power
#: (white highlights), shared with the VTK backend.
AMBIENT, DIFFUSE, SPECULAR, SPECULAR_POWER = 0.15, 0.85, 0.15, 20.0


def render_raster(
    vertices: np.ndarray,
    normals: np.ndarray,
    faces: np.ndarray,
    rgb: np.ndarray | None,
    site: str,
    camera: Camera,
    view_size: tuple[int, int],
    colour: np.ndarray,
) -> np.ndarray:
    """(H, W, 3) uint8 view of the mesh at ``vertices`` (N, 3) m with unit ``normals`` (N, 3),
    ``faces`` (M, 3); ``rgb`` uint8 colours per ``site`` ('point' (N, 3) or 'cell' (M, 3)),
    or None for the plain ``colour`` (3,) sRGB 0-1; ``view_size`` = (W, H) px."""
    width, height = view_size
    view = view_matrix(camera)
    cam_pts = vertices @ view[:, :3].T + view[:, 3]
    raster = rasterize(cam_pts, faces, intrinsics(camera, view_size), (height, width), near=1e-3)
    if rgb is None:
        albedo, per_cell = np.asarray(colour, dtype=np.float64)[None], False
    else:
        albedo, per_cell = np.asarray(rgb, dtype=np.float64) / 255.0, site == "cell"
    image = np.empty((height * width, 3), dtype=np.uint8)
    _shade(
        raster.face.ravel(), raster.bary.reshape(-1, 3), np.ascontiguousarray(faces, np.int64),
        cam_pts, np.ascontiguousarray(normals @ view[:, :3].T), albedo, per_cell,
        np.round(255 * np.asarray(BACKGROUND)), image,
    )  # fmt: skip
    return image.reshape(height, width, 3)


@njit(cache=True, nogil=True)
def _shade(
    face_img: np.ndarray, bary_img: np.ndarray, faces: np.ndarray, cam_pts: np.ndarray,
    normals: np.ndarray, albedo: np.ndarray, per_cell: bool, background: np.ndarray,
    image: np.ndarray,
) -> None:  # fmt: skip
    """Light each covered pixel of the flat raster (``face_img`` (P,), ``bary_img`` (P, 3))
    as VTK's fragment shader does for several directional lights: interpolated normal turned
    towards the eye, ambient + diffuse (n . l) + Phong specular (reflected light . view)^power,
    albedo per vertex, per cell or one (1, 3); background elsewhere; into ``image`` (P, 3)."""
    lights, colours = LIGHT_DIRECTIONS, LIGHT_COLOURS
    n_lights, uniform = lights.shape[0], albedo.shape[0] == 1
    for p in range(face_img.shape[0]):
        f = face_img[p]
        if f < 0:
            for c in range(3):
                image[p, c] = background[c]
            continue
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        w0, w1, w2 = bary_img[p, 0], bary_img[p, 1], bary_img[p, 2]
        nx = w0 * normals[i0, 0] + w1 * normals[i1, 0] + w2 * normals[i2, 0]
        ny = w0 * normals[i0, 1] + w1 * normals[i1, 1] + w2 * normals[i2, 1]
        nz = w0 * normals[i0, 2] + w1 * normals[i1, 2] + w2 * normals[i2, 2]
        ex = -(w0 * cam_pts[i0, 0] + w1 * cam_pts[i1, 0] + w2 * cam_pts[i2, 0])
        ey = -(w0 * cam_pts[i0, 1] + w1 * cam_pts[i1, 1] + w2 * cam_pts[i2, 1])
        ez = -(w0 * cam_pts[i0, 2] + w1 * cam_pts[i1, 2] + w2 * cam_pts[i2, 2])
        scale = 1.0 / max(np.sqrt(nx * nx + ny * ny + nz * nz), 1e-12)
        if nx * ex + ny * ey + nz * ez < 0.0:
            scale = -scale  # two-sided lighting: the normal turned towards the eye
        nx, ny, nz = nx * scale, ny * scale, nz * scale
        scale = 1.0 / max(np.sqrt(ex * ex + ey * ey + ez * ez), 1e-12)
        ex, ey, ez = ex * scale, ey * scale, ez * scale
        dr = dg = db = sr = sg = sb = 0.0
        for k in range(n_lights):
            cos = nx * lights[k, 0] + ny * lights[k, 1] + nz * lights[k, 2]
            if cos <= 0.0:
                continue
            dr += cos * colours[k, 0]
            dg += cos * colours[k, 1]
            db += cos * colours[k, 2]
            # the light reflected about the normal, against the direction to the eye
            rv = (2.0 * cos * nx - lights[k, 0]) * ex + (2.0 * cos * ny - lights[k, 1]) * ey
            rv += (2.0 * cos * nz - lights[k, 2]) * ez
            if rv > 0.0:
                lobe = rv**SPECULAR_POWER
                sr += lobe * colours[k, 0]
                sg += lobe * colours[k, 1]
                sb += lobe * colours[k, 2]
        for c, diffuse, specular in ((0, dr, sr), (1, dg, sg), (2, db, sb)):
            if uniform:
                a = albedo[0, c]
            elif per_cell:
                a = albedo[f, c]
            else:
                a = w0 * albedo[i0, c] + w1 * albedo[i1, c] + w2 * albedo[i2, c]
            v = (AMBIENT + DIFFUSE * diffuse) * a + SPECULAR * specular
            image[p, c] = np.uint8(np.round(255.0 * min(max(v, 0.0), 1.0)))
