"""The lip seam: cutting tets and surfaces, side-aware binding; and embedding in tets."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.spatial import Delaunay

from physanim.evaluate.surfaces import RestTriangles, seam_faces
from physanim.fem.geometry import node_dofs
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.statics import solve_static
from physanim.mesh.embed import embedded_displacements, embedding_matrix
from physanim.mesh.params import TetraParams
from physanim.mesh.seam import (
    _TET_FACES,
    LOWER,
    NONE,
    UPPER,
    MouthLine,
    bind_across_seam,
    cut_surface,
    cut_tets,
)
from physanim.mesh.tetra import orient_and_check
from physanim.store.file_cache import FileCache

#: a curved mouth line across the middle of the block (m)
MOUTH = MouthLine(np.array([[-0.015, 0.0005, 0.0], [0.0, 0.0015, 0.0], [0.015, 0.0005, 0.0]]))


def block(nx=16, ny=11, nz=4):
    """Tets of a grid over [-3, 3] x [-2, 2] x [-1, 0] cm (a slab of tissue), every cube split
    into 6 tets around its main diagonal (Kuhn), so no tet reaches beyond its cube."""
    axes = (np.linspace(-0.03, 0.03, nx), np.linspace(-0.02, 0.02, ny), np.linspace(-0.01, 0, nz))
    g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    idx = np.arange(len(g)).reshape(nx, ny, nz)
    c = np.stack(
        [idx[i : nx - 1 + i, j : ny - 1 + j, k : nz - 1 + k].ravel()
         for i in (0, 1) for j in (0, 1) for k in (0, 1)], axis=1,
    )  # fmt: skip  # cube corners, bit order (i, j, k)
    paths = [(1, 3), (1, 5), (2, 3), (2, 6), (4, 5), (4, 6)]  # 0 -> a -> b -> 7
    tets = np.concatenate([c[:, [0, a, b, 7]] for a, b in paths])
    tets, _ = orient_and_check(g, tets, TetraParams(edge_length_m=0.004))
    return g, tets


def shared_faces_across(tets, side):
    """Interior faces shared by an upper and a lower tet."""
    faces = np.sort(tets[:, _TET_FACES].reshape(-1, 3), axis=1)
    owner = np.repeat(np.arange(len(tets)), 4)
    _, inv, counts = np.unique(faces, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    shared = counts[inv] == 2
    order = np.argsort(inv[shared], kind="stable")
    pairs = owner[shared][order].reshape(-1, 2)
    s = side[pairs]
    return pairs[s[:, 0] * s[:, 1] == -1]


def test_cut_leaves_no_face_between_the_lips_but_at_the_corners() -> None:
    nodes, tets = block()
    tet_side = MOUTH.side(nodes[tets].mean(axis=1))
    before = shared_faces_across(tets, tet_side)
    cut = cut_tets(nodes, tets, MOUTH)
    after = shared_faces_across(cut.elements, tet_side)
    assert len(before) > 40 and cut.n_seam_faces == len(before)
    assert len(cut.parent) > len(nodes)  # seam nodes were duplicated
    # what stays joined is at the mouth corners only (within one grid step)
    x = nodes[tets[after.ravel()]].mean(axis=1)[:, 0]
    assert np.all(np.abs(np.abs(x) - 0.015) < 0.006), x
    # every new node copies an original one at the same place
    assert np.array_equal(cut.parent[: len(nodes)], np.arange(len(nodes)))
    assert set(np.unique(cut.side)) == {LOWER, NONE, UPPER}


def test_cut_lets_the_lower_lip_drop_while_the_upper_lip_stays() -> None:
    """Pull the lower half of the block's bottom face down: across the seam the upper side
    barely moves, while without the cut it is dragged along."""
    nodes, tets = block()
    moved = {}
    for cut_it in (False, True):
        if cut_it:
            cut = cut_tets(nodes, tets, MOUTH)
            x, t = cut.nodes(nodes), cut.elements
        else:
            x, t = nodes, tets
        model = build_model(x, t, TetMaterials.uniform(len(t), 1e5, 0.3, 1.0, 1000.0))
        bottom = np.nonzero(x[:, 2] < -0.0099)[0]
        values = np.zeros((len(bottom), 3))
        values[x[bottom, 1] < 0.0, 1] = -0.002  # the "mandible" drops 2 mm
        dofs = node_dofs(bottom)
        d = solve_static(model.K, dofs, values.ravel()).reshape(-1, 3)
        top = np.nonzero((x[:, 2] > -1e-4) & (np.abs(x[:, 0]) < 0.008))[0]
        upper = top[(x[top, 1] > 0.006) & (x[top, 1] < 0.010)]  # clear of the seam
        moved[cut_it] = np.abs(d[upper, 1]).mean()
    assert moved[True] < 0.5 * moved[False], moved


def test_surface_cut_and_binding_never_cross_the_seam() -> None:
    g = np.stack(np.meshgrid(np.linspace(-0.03, 0.03, 31), np.linspace(-0.02, 0.02, 21)), -1)
    v = np.c_[g.reshape(-1, 2), np.zeros(g.size // 2)]
    f = Delaunay(v[:, :2]).simplices
    cut = cut_surface(v, f, MOUTH)
    vc, fc = cut.nodes(v), cut.elements
    assert cut.n_seam_faces > 10 and len(vc) > len(v)
    b = bind_across_seam(vc, cut.side, vc, fc, MOUTH)
    tri_side = MOUTH.side(vc[fc].mean(axis=1))
    assert not np.any(tri_side[b.triangle] * cut.side == -1)  # never the other lip
    np.testing.assert_allclose(b.distance, 0.0, atol=1e-12)


def test_embedding_reproduces_affine_motion_and_respects_the_seam(tmp_path) -> None:
    """Points embedded in tets move exactly with an affine node displacement (those of a lip
    that lie in the other lip's tets, within 5 um); across the cut, upper-lip points follow
    only upper tets."""
    nodes, tets = block()
    cut = cut_tets(nodes, tets, MOUTH)
    x, t = cut.nodes(nodes), cut.elements
    rng = np.random.default_rng(1)
    pts = rng.uniform([-0.029, -0.019, -0.0099], [0.029, 0.019, 0.0], (400, 3))
    w = embedding_matrix(pts, MOUTH.side(pts), x, t, MOUTH.side(x[t].mean(axis=1)))
    assert isinstance(w, sp.csr_array)
    a = np.array([[0.01, -0.02, 0.005], [0.03, 0.0, -0.01], [0.0, 0.02, 0.01]])
    u = x @ a.T + np.array([1e-3, 0.0, -2e-3])
    affine = pts @ a.T + np.array([1e-3, 0.0, -2e-3])
    # a point of one lip inside the other's tets (the cut follows tet faces, not the line)
    # moves with its own lip's closest boundary point, a hair's breadth away
    other = MOUTH.side(pts) != NONE
    near_cut = other & (np.abs(pts[:, 1] - 0.001) < 0.002)
    np.testing.assert_allclose((w @ u)[~near_cut], affine[~near_cut], atol=1e-12)
    np.testing.assert_allclose((w @ u)[near_cut], affine[near_cut], atol=5e-6)
    frames = embedded_displacements(pts, MOUTH.side(pts), x, t, MOUTH, np.stack([0 * u, u, 2 * u]))
    np.testing.assert_allclose(frames, np.stack([0 * w @ u, w @ u, 2 * w @ u]), atol=1e-12)
    # through a cache: the same answer, the embedding found once for these inputs
    cache, motion = FileCache(tmp_path / "embeddings"), np.stack([0 * u, u, 2 * u])
    for _ in range(2):
        cached = embedded_displacements(pts, MOUTH.side(pts), x, t, MOUTH, motion, cache)
        np.testing.assert_array_equal(cached, frames)
        assert len(list(cache.folder.iterdir())) == 1
    moved_pts = pts + 1e-4
    embedded_displacements(moved_pts, MOUTH.side(moved_pts), x, t, MOUTH, motion, cache)
    assert len(list(cache.folder.iterdir())) == 2
    np.testing.assert_allclose(frames[2][~near_cut], 2 * affine[~near_cut], atol=1e-12)
    # open the lips: lower side nodes drop; upper-lip points do not follow
    drop = np.where((cut.side == LOWER)[:, None], [0.0, -1e-3, 0.0], 0.0)
    moved = w @ drop
    upper = MOUTH.side(pts) == UPPER
    assert upper.sum() > 10 and np.all(moved[upper, 1] == 0.0)


def test_points_outside_the_tets_move_with_their_closest_boundary_point() -> None:
    """Points 0.2-1 mm above the slab's skin (z = 0) under a bending node field u = (0, 0,
    sin(60 x) / 100 m): each moves as its closest point on the skin (the seed's grid search,
    interpolated on that face; Open3D's search is float32), the field is continuous across
    the skin, and a line 1 mm above it moves as the line on it. Extrapolating the nearest
    tet's field instead (the embedding before): 0.32 mm off the closest points, and the line
    above jumped 0.26 mm between neighbours 0.1 mm apart, where the field changes 0.06 mm."""
    from physanim.mesh.binding import bind_points
    from physanim.mesh.kinematic import blend_matrix
    from physanim.mesh.tetra import boundary_faces

    nodes, tets = block()
    side = np.full(len(tets), NONE)
    u = np.c_[np.zeros((len(nodes), 2)), 0.01 * np.sin(60.0 * nodes[:, 0])]
    rng = np.random.default_rng(3)
    above = np.c_[rng.uniform(-0.025, 0.025, (300, 2)), rng.uniform(2e-4, 1e-3, 300)]
    w = embedding_matrix(above, np.full(300, NONE), nodes, tets, side)
    skin = boundary_faces(tets)
    expected = blend_matrix(bind_points(above, nodes, skin), skin, len(nodes)) @ u
    np.testing.assert_allclose(w @ u, expected, atol=5e-8)  # Open3D searches in float32
    line = np.c_[np.linspace(-0.02, 0.02, 401), np.full(401, 0.003), np.zeros(401)]
    across = [embedding_matrix(line + [0, 0, dz], np.full(401, NONE), nodes, tets, side) @ u
              for dz in (-1e-9, 1e-9)]  # fmt: skip
    np.testing.assert_allclose(across[0], across[1], atol=5e-8)
    high = line + [0.0, 0.0, 1e-3]
    moved = (embedding_matrix(high, np.full(401, NONE), nodes, tets, side) @ u)[:, 2]
    along = (embedding_matrix(line, np.full(401, NONE), nodes, tets, side) @ u)[:, 2]
    np.testing.assert_allclose(moved, along, atol=5e-8)


def test_tets_hinged_by_an_edge_or_a_vertex_are_dropped():
    """Two tets sharing a face stay; one joined to them by an edge only and one by a vertex
    only go (each turns about its hinge without strain), with their unused nodes; the kept
    nodes keep their parents and sides, renumbered in order."""
    from physanim.mesh.seam import Cut

    nodes = np.array(
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1],  # two tets on face 1-2-3
         [1, 1, -1], [2, 0, -1],  # a tet on edge 1-2
         [-1, -1, -1], [-1, 0, -1], [0, -1, -1]],  # a tet on vertex 0
        dtype=float,
    )  # fmt: skip
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4], [1, 2, 5, 6], [0, 7, 8, 9]])
    side = np.arange(len(nodes), dtype=np.int8) % 3
    cut = Cut(tets, np.arange(len(nodes)), side, 0)
    kept, dropped = cut.face_connected()
    assert dropped == 2
    np.testing.assert_array_equal(kept.elements, [[0, 1, 2, 3], [1, 2, 3, 4]])
    np.testing.assert_array_equal(kept.parent, [0, 1, 2, 3, 4])
    np.testing.assert_array_equal(kept.side, side[:5])
    assert Cut(tets[:2], np.arange(5), side[:5], 0).face_connected()[1] == 0


def test_the_tets_cut_ends_inside_the_corners_so_a_finer_surface_stays_whole() -> None:
    """The coarse tets' cut never runs on past a mouth corner (no tet with a node there is
    of a lip), so a finer surface cut along the same line and embedded in the tets, its lower
    lip dropped 2 mm, stretches only along its own cut: a tet cut running past the surface's
    stretched the surface triangle between a point of the lower lip and its uncut neighbour
    (4.7 times at the demo's mouth corner). The corners lie inside cubes of the block, so
    tets there straddle them."""
    mouth = MouthLine(np.array([[-0.0125, 0.0005, 0.0], [0.0, 0.0015, 0.0], [0.0125, 0.0005, 0.0]]))
    nodes, tets = block()
    cut = cut_tets(nodes, tets, mouth)
    x, t = cut.nodes(nodes), cut.elements
    reach = x[t][..., 0]
    x_r, x_l = mouth.corners
    past = (reach <= x_r).any(axis=1) | (reach >= x_l).any(axis=1)
    assert past.sum() > 100 and np.all(mouth.element_side(x, t)[past] == NONE)
    g = np.stack(np.meshgrid(np.linspace(-0.03, 0.03, 121), np.linspace(-0.02, 0.02, 81)), -1)
    v = np.c_[g.reshape(-1, 2), np.zeros(g.size // 2)]  # 0.5 mm triangles on the top face
    surface = cut_surface(v, Delaunay(v[:, :2]).simplices, mouth)
    vs, fs = surface.nodes(v), surface.elements
    drop = np.where((cut.side == LOWER)[:, None], [0.0, -2e-3, 0.0], 0.0)
    moved = vs + embedded_displacements(vs, surface.side, x, t, mouth, drop[None])[0]
    stretch, turned = RestTriangles.of(vs, fs).stretch(moved)
    off_seam = ~seam_faces(fs, surface.parent)
    copies = np.flatnonzero(np.arange(len(vs)) >= len(v))  # a seam vertex's second copy
    gap = np.linalg.norm(moved[copies] - moved[surface.parent[copies]], axis=1)
    assert gap.max() > 1.5e-3  # the lips part along the surface's cut
    assert stretch[off_seam].max() < 2.0 and not turned[off_seam].any()
