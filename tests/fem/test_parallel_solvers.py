"""The multithreaded LDL^T solve and CSR products against dense / scipy ground truth."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from physanim.fem.geometry import node_dofs
from physanim.fem.linsolve import CholmodFactors, factorize, factorize_split, has_cholmod
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.parallel_ldl import ParallelLDL
from physanim.fem.parallel_spmv import ParallelCSR, SymmetricQuadraticForm
from physanim.fem.params import SimulateParams
from tests.fem.fem_meshes import box_mesh

needs_cholmod = pytest.mark.skipif(not has_cholmod(), reason="scikit-sparse not installed")


def _dense_ldl(A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unpivoted A = L D L^T of a small dense matrix (L unit lower)."""
    n = len(A)
    L, d = np.eye(n), np.zeros(n)
    for j in range(n):
        d[j] = A[j, j] - (L[j, :j] ** 2) @ d[:j]
        L[j + 1 :, j] = (A[j + 1 :, j] - L[j + 1 :, :j] @ (d[:j] * L[j, :j])) / d[j]
    return L, d


@pytest.mark.parametrize("n_threads", [1, 2, 3])
def test_ldl_solve_on_a_tree_that_is_not_postordered(n_threads):
    # elimination tree 0 -> 2 -> 3, 1 -> 3: node 1 sits inside the subtree range of 2
    A = np.array(
        [[4.0, 0, 1, 0], [0, 3.0, 0, 1], [1, 0, -5.0, 1], [0, 1, 1, 6.0]]
    )  # indefinite: D has a negative entry
    L, d = _dense_ldl(A)
    perm = np.array([2, 0, 3, 1])  # (P b)[i] = b[perm[i]]; A_orig = P^T A P
    A_orig = np.zeros_like(A)
    A_orig[np.ix_(perm, perm)] = A
    b = np.array([1.0, -2.0, 0.5, 3.0])
    x = ParallelLDL(sp.csc_matrix(L), d, perm, n_threads)(b)
    np.testing.assert_allclose(A_orig @ x, b, rtol=1e-13, atol=1e-13)


def _tet_model():
    nodes, tets = box_mesh((6, 5, 4), (0.06, 0.05, 0.02))
    model = build_model(nodes, tets, TetMaterials.uniform(len(tets)), SimulateParams())
    fixed = np.flatnonzero(nodes[:, 2] < 1e-9)
    pres = node_dofs(fixed)
    free = np.setdiff1d(np.arange(model.n_dofs), pres)
    dt = 1e-3
    A_el = model.split[0] + 4 / dt**2 * model.M + 2 / dt * model.C
    return model, free, sp.csr_matrix(A_el)[free][:, free], sp.csr_matrix(model.split[1])[:, free]


@needs_cholmod
@pytest.mark.parametrize("n_threads", [1, 2, 4])
def test_ldl_solve_of_a_cholmod_factor_matches_scipy(n_threads):
    from sksparse.cholmod import cholesky

    model, free, A_el, G = _tet_model()
    w = model.split[2]
    aug = sp.bmat([[A_el, G.T], [G, sp.diags(-1.0 / w)]], format="csc")  # quasi-definite
    factor = cholesky(aug, mode="simplicial")
    L, D = factor.L_D()
    solve = ParallelLDL(L, D.diagonal(), factor.P(), n_threads)
    B = np.random.default_rng(0).normal(size=(aug.shape[0], 2))
    X = solve(B)
    ref = spla.spsolve(aug.tocsc(), B)
    np.testing.assert_allclose(X, ref, rtol=0, atol=1e-11 * np.abs(ref).max())
    if n_threads > 1:
        assert solve.top_sn.size > 0 and np.diff(solve.bin_ptr).min() > 0  # really split


@needs_cholmod
def test_split_and_direct_cholmod_solvers_match_superlu():
    model, free, A_el, G = _tet_model()
    w = model.split[2]
    A = (A_el + G.T @ sp.diags(w) @ G).tocsc()
    b = np.random.default_rng(1).normal(size=A.shape[0])
    ref = factorize(A, "superlu")(b)
    for x in (factorize(A, "cholmod")(b), factorize_split(A_el, G, w, "cholmod")(b)):
        np.testing.assert_allclose(x, ref, rtol=0, atol=1e-10 * np.abs(ref).max())


@needs_cholmod
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_refactorised_pattern_reuses_the_solver_structure(dtype):
    # Newmark matrices at three step sizes: one symbolic analysis, refilled solvers
    model, free, A_el, G = _tet_model()
    w = model.split[2]
    K = (A_el + G.T @ sp.diags(w) @ G).tocsc()
    M = sp.csr_matrix(model.M)[free][:, free]
    factors = CholmodFactors("supernodal", dtype)
    b = np.random.default_rng(4).normal(size=K.shape[0])
    tol = 1e-10 if dtype == np.float64 else 1e-5
    solvers = []
    for c0 in (1e4, 1e6, 1e8):
        A = (K + c0 * M).tocsc()
        solve = factors(A)
        solvers.append(solve)
        ref = spla.spsolve(A, b)
        np.testing.assert_allclose(solve(b), ref, rtol=0, atol=tol * np.abs(ref).max())
    assert solvers[2].rows is solvers[0].rows  # structure shared, values not
    assert solvers[2].vals is not solvers[0].vals and solvers[0].vals.dtype == dtype
    # the first solver still solves its own matrix after the others were made
    ref = spla.spsolve((K + 1e4 * M).tocsc(), b)
    np.testing.assert_allclose(solvers[0](b), ref, rtol=0, atol=tol * np.abs(ref).max())


@pytest.mark.parametrize("n_threads", [1, 2, 5])
def test_parallel_csr_product_and_quadratic_form(n_threads):
    rng = np.random.default_rng(2)
    A = sp.random(300, 280, density=0.05, random_state=3, format="csr")
    x = rng.normal(size=280)
    P = ParallelCSR(A, n_threads)
    np.testing.assert_allclose(P @ x, A @ x, rtol=1e-13, atol=1e-14)
    S = (A[:, :280] @ A[:, :280].T)[:280][:, :280] - sp.eye(280)  # symmetric, indefinite
    y = rng.normal(size=280)
    q = SymmetricQuadraticForm(S, n_threads)
    assert q(y) == pytest.approx(y @ (S @ y), rel=1e-12)
    assert q.data.size < 0.6 * S.nnz  # only the upper triangle is stored


@pytest.mark.parametrize("nested", [True, False])
def test_common_pattern_combines_matrices_exactly(nested):
    """K, M, C values on one pattern: any combination of the value arrays is the sparse sum,
    whether one pattern holds the others (the demo) or they only overlap."""
    from physanim.fem.newmark import _common_pattern

    rng = np.random.default_rng(5)
    n = 60
    big = sp.random(n, n, density=0.2, random_state=rng)
    big = (big + big.T + sp.eye(n)).tocsr()
    if nested:  # a sub-pattern of big: some of its entries, scaled
        small = big.multiply(sp.random(n, n, density=0.5, random_state=rng) > 0)
        small = (small + small.T).tocsr()
    else:
        small = sp.random(n, n, density=0.1, random_state=rng)
        small = (small + small.T).tocsr()
    third = (2.0 * big).tocsr()
    pattern, (a, b, c) = _common_pattern(big, small, third)
    combined = pattern.copy()
    combined.data = a + 3.0 * b - 0.5 * c
    expected = big + 3.0 * small - 0.5 * third
    np.testing.assert_allclose(combined.toarray(), expected.toarray(), rtol=0, atol=1e-12)
    assert pattern.has_sorted_indices
