"""The multithreaded LDL^T solve and CSR products against dense / scipy ground truth."""

from __future__ import annotations

import numba
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from physanim.fem.geometry import node_dofs
from physanim.fem.linsolve import CholmodFactors, factorize, factorize_split, has_cholmod
from physanim.fem.materials import TetMaterials
from physanim.fem.model import build_model
from physanim.fem.numba_threads import ThreadTrials, keeps_thread_count
from physanim.fem.parallel_ldl import ParallelLDL
from physanim.fem.parallel_spmv import ParallelCSR, SymmetricQuadraticForm
from physanim.fem.params import SimulateParams
from tests.fem.fem_meshes import box_mesh

needs_cholmod = pytest.mark.skipif(
    not has_cholmod(), reason="CHOLMOD (scikit-sparse) not installed: CHOLMOD check not run"
)


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


@pytest.mark.parametrize("n_threads", [1, 2])
def test_cholesky_factors_solve_postordered_or_not(n_threads):
    """A Cholesky factor is packed straight from its CSC arrays when its elimination tree is
    postordered (CHOLMOD's) and through the general path when not; its refills solve their
    own matrices whichever way they are given (L L^T, or unit L with D)."""
    rng = np.random.default_rng(7)
    # tree 0 -> 2 -> 3, 1 -> 3: node 1 sits inside the subtree range of 2 (not postordered)
    unordered = np.array([[4.0, 0, 1, 0], [0, 3.0, 0, 1], [1, 0, 5.0, 1], [0, 1, 1, 6.0]])
    ordered = np.array([[4.0, 1, 0, 1], [1, 5.0, 0, 0], [0, 0, 3.0, 1], [1, 0, 1, 6.0]])
    perm = np.array([2, 0, 3, 1])  # (P b)[i] = b[perm[i]]; A_orig = P^T A P
    for A, postordered in ((ordered, True), (unordered, False)):
        solver = None
        for scale in (1.0, 2.0, 3.0):  # same pattern, new values
            As = A + scale * np.diag(rng.uniform(1, 2, 4))
            L = sp.csc_matrix(np.linalg.cholesky(As))
            A_orig = np.zeros_like(As)
            A_orig[np.ix_(perm, perm)] = As
            if solver is None:
                solver = ParallelLDL.from_cholesky(L, perm, n_threads)
                assert (solver._q is None) == postordered
            elif scale == 2.0:
                solver = solver.refilled_cholesky(L)
            else:
                d = L.diagonal()
                solver = solver.refilled(sp.csc_matrix(L / d), d**2)
            b = rng.normal(size=4)
            np.testing.assert_allclose(A_orig @ solver(b), b, rtol=1e-13, atol=1e-13)


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs 2 numba threads")
def test_thread_trials_switch_only_when_the_other_count_was_faster():
    """Every 30th frame runs on the other thread count; the run moves to it when that frame
    was faster per solve than 0.9 x the recent median, and moves back the same way."""

    @keeps_thread_count
    def run(seconds_by_threads: dict[int, float], sizes: dict[int, float]) -> list[int]:
        numba.set_num_threads(2)
        trials, used = ThreadTrials(most=2), []
        for k in range(1, 91):
            threads = trials.start(k)
            used.append(threads)
            size = sizes.get(k, 1.0)
            trials.finish(seconds_by_threads[threads] * size, size)
        return used

    # cores free: one thread is slower, the trials at frames 30, 60, 90 change nothing
    used = run({2: 1.0, 1: 1.6}, {})
    assert [k for k, t in enumerate(used, 1) if t == 1] == [30, 60, 90]
    # cores busy: one thread wins at frame 30 and keeps winning; two are tried at 60 and 90
    used = run({2: 3.0, 1: 1.0}, {})
    assert used[:29] == [2] * 29 and used[29:59] == [1] * 30 and used[59] == 2
    assert used[89] == 2 and set(used[60:89]) == {1}
    # a trial frame with twice the solves is judged per solve: 1.6 s for 2 solves wins
    used = run({2: 1.0, 1: 0.8}, {30: 2.0})
    assert used[30:59] == [1] * 29
    assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS


def _two_branches(n: int) -> np.ndarray:
    """An SPD matrix whose elimination tree has two chains of ``n`` joined at a last node
    (the partition puts them in different pieces; the last row sums both)."""
    T = 4.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    A = np.zeros((2 * n + 1, 2 * n + 1))
    A[:n, :n] = A[n : 2 * n, n : 2 * n] = T
    A[-1, -1] = 4.0
    A[-1, [n - 1, 2 * n - 1]] = A[[n - 1, 2 * n - 1], -1] = -1.0
    return A


@pytest.mark.skipif(
    numba.config.NUMBA_NUM_THREADS < 2, reason="one numba thread: nothing to compare"
)
@keeps_thread_count
def test_results_do_not_depend_on_the_thread_count_in_use():
    """The solve, the products and the quadratic form split their work by numba's pool
    size, not by the thread count set when they were built or run: ``simulate`` lowers it to
    1 when that is faster (cores busy), and its results are the same bytes either way (they
    differed in the last bits when the pieces followed the thread count)."""
    L, d = _dense_ldl(_two_branches(60))
    rng = np.random.default_rng(3)
    b = rng.normal(size=(len(d), 2))
    K = sp.csr_matrix(_tet_model()[0].K)
    x = rng.normal(size=K.shape[0])
    most = numba.config.NUMBA_NUM_THREADS
    out = []
    for built, run in ((most, most), (1, most), (1, 1), (most, 1)):
        numba.set_num_threads(built)
        solve = ParallelLDL(sp.csc_matrix(np.tril(L, -1)), d, np.arange(len(d)))
        product, energy = ParallelCSR(K), SymmetricQuadraticForm(K)
        numba.set_num_threads(run)
        out.append((solve(b).tobytes(), (product @ x).tobytes(), energy(x)))
    assert all(o == out[0] for o in out)
