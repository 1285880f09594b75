"""Synthetic mesh animations for the export tests: a bumpy sheet moved by three modes."""

from __future__ import annotations

import numpy as np
import pytest

from physanim.export.animation import MeshAnimation

#: Frame rate of the synthetic animations, frames/s (not Blender's default 24, so that a
#: file read at the wrong rate shows).
FPS = 30.0


def sheet(n: int = 24, size_m: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """A bumpy square sheet in the xy plane facing +z: (n*n, 3) m vertices, (2(n-1)^2, 3)
    counter-clockwise triangles."""
    g = np.linspace(-size_m / 2, size_m / 2, n)
    x, y = (a.ravel() for a in np.meshgrid(g, g))
    vertices = np.stack([x, y, 0.01 * np.cos(40 * x) * np.cos(30 * y)], axis=1)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    faces = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return vertices, faces


def three_modes(frames: int = 12, fps: float = FPS, name: str = "fem") -> MeshAnimation:
    """The sheet moved by three independent modes (a 5 mm bulge, a 2 mm shear, a 0.5 mm
    ripple) with unrelated time courses: an animation of rank exactly 3."""
    vertices, faces = sheet()
    x, y = vertices[:, 0], vertices[:, 1]
    bulge = np.exp(-(x**2 + y**2) / 1e-3)[:, None] * [0.0, 0.0, 0.005]
    shear = (y / 0.05)[:, None] * [0.002, 0.0, 0.0]
    ripple = np.sin(60 * x)[:, None] * [0.0, 0.0005, 0.0005]
    t = np.arange(frames) / fps
    courses = np.stack([np.sin(2 * np.pi * t), np.cos(3 * t) ** 2, np.sin(7 * t + 1)], axis=1)
    points = vertices + np.einsum("tk,kni->tni", courses, np.stack([bulge, shear, ripple]))
    return MeshAnimation(name, points, faces, fps)


@pytest.fixture
def modes() -> MeshAnimation:
    """A 12-frame rank-3 animation of a 576-vertex sheet at 30 fps."""
    return three_modes()
