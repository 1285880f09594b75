"""VTK backend of the face renders: pyvista/VTK offscreen (EGL or OSMesa, no display needed),
Gouraud-shaded, lit by VTK's light kit. One plotter per sequence, points/normals/colours
updated in place. A VTK crash kills its process: sequences run it isolated
(:mod:`physanim.render.isolated`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from physanim.cameras import Camera
from physanim.render.colours import BACKGROUND
from physanim.render.raster_backend import AMBIENT, DIFFUSE, SPECULAR, SPECULAR_POWER


class VtkView:
    """Offscreen VTK view of one mesh topology ``faces`` (M, 3) at ``view_size`` = (W, H) px;
    ``colour`` (3,) sRGB 0-1 of the skin when no colours are drawn. Call ``close``."""

    def __init__(self, faces: np.ndarray, view_size: tuple[int, int], colour: np.ndarray) -> None:
        self.faces, self.view_size, self.colour = faces, view_size, colour
        self._plotter = None
        self._mesh = None

    def close(self) -> None:
        """Release the VTK render window."""
        if self._plotter is not None:
            self._plotter.close()
            self._plotter = None

    def render(
        self,
        vertices: np.ndarray,
        normals: np.ndarray,
        rgb: np.ndarray | None,
        site: str,
        cameras: Sequence[Camera],
    ) -> list[np.ndarray]:
        """(H, W, 3) uint8 views of the mesh, one per camera (the mesh uploaded once);
        arguments as in :func:`.raster_backend.render_raster`."""
        import pyvista as pv

        if self._plotter is None:
            pv.OFF_SCREEN = True
            cells = np.hstack([np.full((len(self.faces), 1), 3), self.faces]).ravel()
            mesh = pv.PolyData(vertices.copy(), cells)
            mesh.point_data["Normals"] = normals
            mesh.point_data.active_normals_name = "Normals"
            plotter = pv.Plotter(off_screen=True, window_size=self.view_size)
            plotter.render_window.SetMultiSamples(0)  # MSAA is 4-5x slower on llvmpipe
            plotter.set_background(BACKGROUND)
            style = dict(
                ambient=AMBIENT, diffuse=DIFFUSE, specular=SPECULAR, specular_power=SPECULAR_POWER
            )
            if rgb is None:
                actor = plotter.add_mesh(
                    mesh, color=tuple(self.colour), interpolation="gouraud", **style
                )
            else:
                data = mesh.point_data if site == "point" else mesh.cell_data
                data["rgb"] = rgb
                actor = plotter.add_mesh(
                    mesh, scalars="rgb", rgb=True, interpolation="gouraud", **style
                )
            # white highlights (VTK's SetColor also tints them, by the theme's colour with
            # scalars), as the project's own backend draws them
            actor.prop.specular_color = (1.0, 1.0, 1.0)
            self._plotter, self._mesh = plotter, mesh
        mesh = self._mesh
        mesh.points[:] = vertices
        mesh.point_data["Normals"][:] = normals
        if rgb is not None:
            (mesh.point_data if site == "point" else mesh.cell_data)["rgb"][:] = rgb
        mesh.Modified()
        return [self._shoot(camera) for camera in cameras]

    def _shoot(self, camera: Camera) -> np.ndarray:
        """(H, W, 3) uint8: the current mesh seen by ``camera``."""
        cam = self._plotter.camera
        cam.position, cam.focal_point, cam.up = camera.position, camera.focal_point, camera.view_up
        cam.view_angle = camera.view_angle
        self._plotter.reset_camera_clipping_range()
        self._plotter.render()
        return np.ascontiguousarray(self._plotter.screenshot(return_img=True)[..., :3])
