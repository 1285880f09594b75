"""Scan loading and cleaning: units, plausibility check, components, holes, crop."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from physanim.mesh.scan_io import ScanError, clean_scan, face000_path, load_scan


def grid(n: int, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Flat n x n vertex grid in z = 0 (m) and its 2 (n-1)^2 triangles."""
    xs, ys = np.meshgrid(np.arange(n) * spacing, np.arange(n) * spacing)
    v = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(n * n)])
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    f = np.concatenate(
        [np.column_stack([a, a + 1, a + n + 1]), np.column_stack([a, a + n + 1, a + n])]
    )
    return v, f


def boundary_edges(faces: np.ndarray) -> int:
    e = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return int((counts == 1).sum())


def test_load_face000_in_metres() -> None:
    v, f = load_scan(face000_path(), "mm")
    assert v.shape == (85849, 3) and v.dtype == np.float64 and f.dtype == np.int64
    assert 0.1 < np.ptp(v, axis=0).max() < 0.3


def test_wrong_unit_names_file_and_suggests_unit() -> None:
    with pytest.raises(ScanError, match=r"face000\.ply.*units='mm'"):
        load_scan(face000_path(), "m")


def test_missing_and_unsupported_files(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nope.ply"):
        load_scan(tmp_path / "nope.ply", "mm")
    bad = tmp_path / "scan.xyz"
    bad.write_text("0 0 0\n")
    with pytest.raises(ScanError, match="unsupported"):
        load_scan(bad, "mm")


@pytest.mark.parametrize("suffix", [".ply", ".obj", ".stl"])
def test_each_format_loads_the_same_connected_surface(tmp_path: Path, suffix: str) -> None:
    """A 12 x 12 grid written by Open3D reads back with its 144 shared vertices and 242
    triangles in every format (STL stores each corner per triangle: they are merged)."""
    import open3d as o3d

    v, f = grid(12, 0.01)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(v), o3d.utility.Vector3iVector(f))
    mesh.compute_triangle_normals()  # STL stores a normal per triangle
    path = tmp_path / f"scan{suffix}"
    assert o3d.io.write_triangle_mesh(str(path), mesh)
    lv, lf = load_scan(path, "m")
    assert lv.shape == (144, 3) and lf.shape == (242, 3)
    np.testing.assert_allclose(np.sort(lv, axis=0), np.sort(v, axis=0), atol=1e-6)
    corners = np.sort(lv[lf].reshape(len(lf), -1), axis=0)  # same triangles, any numbering
    np.testing.assert_allclose(corners, np.sort(v[f].reshape(len(f), -1), axis=0), atol=1e-6)


def test_loading_never_moves_the_working_directory(tmp_path: Path) -> None:
    """Stages run side by side in threads: a relative path another thread opens while a scan
    loads must still name the same file (pymeshlab's loader changed directory meanwhile)."""
    import threading

    seen, done = set(), threading.Event()

    def watch() -> None:
        while not done.is_set():
            seen.add(os.getcwd())

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        load_scan(face000_path(), "mm")
    finally:
        done.set()
        watcher.join()
    assert seen == {os.getcwd()}


def test_damaged_file_is_named(tmp_path: Path) -> None:
    bad = tmp_path / "scan.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 9\n")
    with pytest.raises(ScanError, match=r"scan\.ply: cannot read a triangle mesh"):
        load_scan(bad, "mm")


def test_clean_keeps_largest_component_and_closes_small_hole() -> None:
    v, f = grid(12, 0.01)
    full = len(f)
    # Punch a hole: drop the two triangles of one interior quad (a 4-edge hole).
    hole = np.nonzero((f == 5 * 12 + 5).any(axis=1) & (f == 6 * 12 + 6).any(axis=1))[0]
    f = np.delete(f, hole, axis=0)
    # Add an island, a duplicate face (other winding start) and a degenerate face.
    island = np.array([[1.0, 1.0, 0.0], [1.01, 1.0, 0.0], [1.0, 1.01, 0.0]])
    f = np.vstack([f, [len(v), len(v) + 1, len(v) + 2], np.roll(f[0], 1), [0, 0, 1]])
    v = np.vstack([v, island])
    v2, f2 = clean_scan(v, f, max_hole_edges=8)
    assert len(v2) == 144 and len(f2) == full
    assert boundary_edges(f2) == 4 * 11  # only the outer border remains open
    v3, f3 = clean_scan(v, f, max_hole_edges=0)
    assert len(f3) == full - 2 and boundary_edges(f3) == 4 * 11 + 4


def test_clean_crop_radius() -> None:
    v, f = grid(21, 0.01)
    centre = np.array([0.1, 0.1, 0.0])
    v2, f2 = clean_scan(v, f, max_hole_edges=0, crop_radius_m=0.05, crop_center=centre)
    assert np.linalg.norm(v2 - centre, axis=1).max() <= 0.05 + 1e-12
    assert len(v2) == int((np.linalg.norm(v - centre, axis=1) <= 0.05).sum())
    with pytest.raises(ValueError, match="crop_radius_m"):
        clean_scan(v, f, crop_radius_m=0.001, crop_center=np.array([5.0, 5.0, 5.0]))
