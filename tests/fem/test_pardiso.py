"""The MKL PARDISO binding against scipy's direct solves on a tetrahedral FEM matrix."""

from __future__ import annotations

import gc

import numba
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from physanim.fem.linsolve import SymmetricFactors, factorize, factorize_split
from physanim.fem.numba_threads import keeps_thread_count
from physanim.fem.pardiso import PardisoFactors, has_pardiso
from tests.fem.test_parallel_solvers import _tet_model

pytestmark = pytest.mark.skipif(not has_pardiso(), reason="MKL (pip install mkl) not installed")


def _augmented(A_el: sp.spmatrix, G: sp.spmatrix, w: np.ndarray) -> sp.csc_matrix:
    return sp.bmat([[A_el, G.T], [G, sp.diags(-1.0 / w)]], format="csc")


@pytest.mark.parametrize("dtype, tol", [(np.float64, 1e-10), (np.float32, 1e-5)])
def test_quasi_definite_ldl_solves_the_anp_matrix(dtype, tol):
    # the augmented one-ring matrix, solved for A_el + G^T diag(w) G's unknowns
    model, free, A_el, G = _tet_model()
    w = model.split[2]
    A = (A_el + G.T @ sp.diags(w) @ G).tocsc()
    B = np.random.default_rng(1).normal(size=(A.shape[0], 3))
    ref = spla.spsolve(A, B)
    solve = factorize_split(A_el, G, w, "pardiso", PardisoFactors("indefinite", dtype))
    for b, r in ((B[:, 0], ref[:, 0]), (B, ref)):
        np.testing.assert_allclose(solve(b), r, rtol=0, atol=tol * np.abs(ref).max())
    np.testing.assert_allclose(factorize(A, "pardiso")(B), ref, atol=1e-10 * np.abs(ref).max())


def test_refactorised_pattern_shares_one_analysis_and_frees_its_slots():
    # Newmark matrices at three step sizes on one analysis; a dropped solver's slot is reused
    model, free, A_el, G = _tet_model()
    w = model.split[2]
    M = sp.csr_matrix(model.M)[free][:, free]
    factors = PardisoFactors("indefinite", np.float64, slots=2)
    b = np.random.default_rng(4).normal(size=A_el.shape[0] + G.shape[0])
    solvers = [factors(_augmented(A_el + c0 * M, G, w)) for c0 in (1e4, 1e6)]
    assert len(factors._handles) == 1 and sorted(s.slot for s in solvers) == [1, 2]
    assert solvers[0].inertia == (A_el.shape[0], G.shape[0])  # quasi-definite: n +, k -
    for c0, solve in zip((1e4, 1e6), solvers, strict=True):
        ref = spla.spsolve(_augmented(A_el + c0 * M, G, w), b)
        np.testing.assert_allclose(solve(b), ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    third = factors(_augmented(A_el + 1e8 * M, G, w))  # both slots taken: a second analysis
    assert len(factors._handles) == 2
    del solvers[0], third
    gc.collect()
    again = factors(_augmented(A_el + 1e8 * M, G, w))
    assert again.handle is factors._handles[0] and again.slot == 1  # freed slot reused
    ref = spla.spsolve(_augmented(A_el + 1e8 * M, G, w), b)
    np.testing.assert_allclose(again(b), ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    # the first slot's factor is gone; the second still solves its own matrix
    ref = spla.spsolve(_augmented(A_el + 1e6 * M, G, w), b)
    np.testing.assert_allclose(solvers[0](b), ref, rtol=0, atol=1e-10 * np.abs(ref).max())


def test_bad_matrices_are_refused_with_their_reason():
    model, free, A_el, G = _tet_model()
    w = model.split[2]
    with pytest.raises(ValueError, match="not quasi-definite"):  # A_el made indefinite
        factorize_split(A_el - 2 * sp.diags(A_el.diagonal()), G, w, "pardiso")
    with pytest.raises(RuntimeError, match="not positive definite"):
        factorize(-A_el, "pardiso")
    factors = PardisoFactors("spd")
    factors(A_el)
    with pytest.raises(ValueError, match="pattern differs"):
        factors(A_el + sp.eye(A_el.shape[0], k=A_el.shape[0] - 1))


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread: nothing to compare")
@keeps_thread_count
def test_results_do_not_depend_on_the_thread_count_numba_runs_on():
    # the FEM lowers numba's thread count when a core is busy; PARDISO keeps the pool size,
    # so a frame's solve is the same bytes either way (its factor and sweeps split by it)
    model, free, A_el, G = _tet_model()
    w = model.split[2]
    b = np.random.default_rng(5).normal(size=(A_el.shape[0], 2))
    got = []
    for threads in (numba.config.NUMBA_NUM_THREADS, 1):
        numba.set_num_threads(threads)
        solve = factorize_split(A_el, G, w, "pardiso", PardisoFactors("indefinite", np.float32))
        got.append(solve(b))
    np.testing.assert_array_equal(got[0], got[1])


def test_symmetric_factors_take_the_ldl_only_where_the_matrix_is_indefinite():
    # a large-strain tangent is indefinite away from equilibrium: the LL^T refuses it and the
    # Bunch-Kaufman LDL^T solves it; definite matrices of one pattern share one LL^T analysis
    model, free, A_el, G = _tet_model()
    A = sp.csr_matrix(A_el)
    b = np.random.default_rng(6).normal(size=(A.shape[0], 2))
    factors = SymmetricFactors()
    shifted = A - sp.diags(np.full(A.shape[0], np.median(A.diagonal())))
    for matrix in (A, 2 * A, shifted):
        ref = spla.spsolve(matrix.tocsc(), b)
        got = factors(matrix)(b)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    assert len(factors._factors["spd"]._handles) == 1
    assert factors._factors["indefinite"]._handles[0].n == A.shape[0]
    other = A + sp.eye(A.shape[0], k=A.shape[0] - 1) + sp.eye(A.shape[0], k=1 - A.shape[0])
    ref = spla.spsolve(other.tocsc(), b)  # another pattern: analysed afresh
    np.testing.assert_allclose(factors(other)(b), ref, rtol=0, atol=1e-9 * np.abs(ref).max())
