"""Multithreaded triangular solves with a fixed sparse LDL^T factor (from CHOLMOD).

Why our own solve: per Newmark step the FEM spends most of its time in the two triangular
sweeps with the constant factor. CHOLMOD's simplicial solve runs on one core and holds the
GIL; its supernodal solve (which could use a threaded BLAS) is LL^T only, so it cannot take
the quasi-definite augmented matrix of the 'anp' formulation, and on the combined SPD matrix
its factor is twice as large. The sweeps are memory-bound, so this solve (1) stores the
factor as dense column blocks of its fundamental supernodes (one row index per block row
instead of one per entry: ~8.4 instead of 12 bytes per entry on a face mesh) and (2) splits
the elimination tree into disjoint subtrees, one group per thread (Geist-Ng), which are
independent in both sweeps; the top separator's supernodes follow one at a time, each split
over the threads by rows (forward) or columns (backward).

A (n, n) = P^T L D L^T P with L unit lower triangular, D diagonal (any sign), P a
permutation; ``perm[i]`` is the original index of permuted row i.
"""

from __future__ import annotations

import copy
import heapq

import numpy as np
import scipy.sparse as sp
from numba import njit, prange

from physanim.fem.numba_threads import work_partitions  # sets the threading layer first

U0, U1 = np.uint64(0), np.uint64(1)


@njit(cache=True)
def _subtree_sizes(parent: np.ndarray) -> np.ndarray:
    size = np.ones(parent.size, np.int64)
    for j in range(parent.size):
        if parent[j] >= 0:
            size[parent[j]] += size[j]
    return size


@njit(cache=True)
def _postorder(parent: np.ndarray) -> np.ndarray:
    """Order of the nodes in which every subtree is a contiguous range ending at its root."""
    n = parent.size
    head = np.full(n, -1, np.int64)  # children as linked lists, kept in increasing order
    nxt = np.full(n, -1, np.int64)
    for j in range(n - 1, -1, -1):
        if parent[j] >= 0:
            nxt[j] = head[parent[j]]
            head[parent[j]] = j
    order = np.empty(n, np.int64)
    stack = np.empty(n, np.int64)
    k = 0
    for root in range(n):
        if parent[root] >= 0:
            continue
        top = 0
        stack[0] = root
        while top >= 0:
            j = stack[top]
            c = head[j]
            if c == -1:
                order[k] = j
                k += 1
                top -= 1
            else:
                head[j] = nxt[c]
                top += 1
                stack[top] = c
    return order


@njit(cache=True)
def _first_descendants(parent: np.ndarray) -> np.ndarray:
    first = np.arange(parent.size)
    for j in range(parent.size):
        if parent[j] >= 0:
            first[parent[j]] = min(first[parent[j]], first[j])
    return first


def _is_postordered(parent: np.ndarray) -> bool:
    """Whether every subtree of the forest ``parent`` is the contiguous range of nodes that
    ends at its root."""
    size = _subtree_sizes(parent)
    return bool(np.array_equal(_first_descendants(parent), np.arange(parent.size) - size + 1))


@njit(cache=True)
def _subtree_weights(parent: np.ndarray, weight: np.ndarray) -> np.ndarray:
    total = weight.astype(np.float64)
    for j in range(parent.size):
        if parent[j] >= 0:
            total[parent[j]] += total[j]
    return total


def _partition(
    parent: np.ndarray, weight: np.ndarray, n_bins: int
) -> tuple[np.ndarray, list[list[int]]]:
    """Split the elimination forest into ``n_bins`` groups of disjoint subtrees plus a top.

    Greedy (Geist-Ng): repeatedly move the heaviest candidate subtree's root to the top set
    and its children into the candidates, pack candidates into bins (largest first), and keep
    the split with the smallest estimated time top + max(bin) (the top's supernodes are swept
    one at a time, each split over all threads). Moving a root with one child shortens that
    subtree by the root's weight, which the top gains: the bins lose at most what the top
    gains, so the estimate does not fall (up to the packing heuristic's slack) and the packing
    is skipped along such chains (the top separator's thousands of columns on a face mesh:
    0.1 s of Python; the demo's partition is the same for 2-8 threads). Returns (is_top (n,)
    bool, roots of the subtrees in each bin).
    """
    n = parent.size
    sub = _subtree_weights(parent, weight)
    # children of j: kids[first[j]:first[j + 1]], ascending (numpy, not n Python lists: those
    # cost 0.1 s on the demo, mostly the garbage collector's passes they set off)
    kids = np.flatnonzero(parent >= 0)
    kids = kids[np.argsort(parent[kids], kind="stable")]
    first = np.searchsorted(parent[kids], np.arange(n + 1))
    heap = [(-sub[j], int(j)) for j in np.flatnonzero(parent < 0)]
    heapq.heapify(heap)
    top: list[int] = []
    top_w = 0.0
    best = (np.inf, 0, [])
    pack = True
    for _ in range(n):
        if pack:
            bins = [0.0] * n_bins
            members: list[list[int]] = [[] for _ in range(n_bins)]
            for w, j in sorted(heap):
                b = min(range(n_bins), key=bins.__getitem__)
                bins[b] -= w
                members[b].append(j)
            cost = top_w + max(bins)
            if cost < best[0]:
                best = (cost, len(top), members)
        j = heap[0][1]
        if n_bins == 1 or first[j] == first[j + 1] or top_w >= best[0]:
            break
        heapq.heappop(heap)
        top.append(j)
        top_w += weight[j]
        for c in kids[first[j] : first[j + 1]].tolist():
            heapq.heappush(heap, (-sub[c], c))
        pack = first[j + 1] - first[j] > 1
    is_top = np.zeros(n, bool)
    is_top[top[: best[1]]] = True
    return is_top, best[2]


@njit(cache=True)
def _pack_rows(indptr, indices, skip, starts, widths, roff, rows):
    """Each supernode's block row indices: those of its last column below the diagonal (CSC
    columns with ``skip`` leading diagonal entries: 0 or 1)."""
    for s in range(starts.size):
        last = starts[s] + widths[s] - 1
        p = indptr[last] + skip
        for r in range(roff[s + 1] - roff[s]):
            rows[roff[s] + r] = indices[p + r]


@njit(cache=True)
def _pack_values(indptr, data, skip, cholesky, starts, widths, roff, boff, toff, vals, tri, dinv):
    """Copy each supernode's columns below the diagonal (CSC ``data``, ``skip`` leading
    diagonal entries per column) into a dense column-major block and its unit triangle.
    ``cholesky``: the columns are a factor of A = L L^T (diagonal first), divided by their
    diagonal entries on the way: the unit L of A = L' D L'^T, D = diag(L)^2, and dinv =
    1 / diag(L)^2 is written too."""
    for s in range(starts.size):
        c0, w = starts[s], widths[s]
        m = roff[s + 1] - roff[s]
        for b in range(w):
            p = indptr[c0 + b]
            inv = 1.0
            if cholesky:
                inv = 1.0 / data[p]
                dinv[c0 + b] = inv * inv
            for a in range(b + 1, w):
                tri[toff[s] + b * w + a] = data[p + skip + a - b - 1] * inv
            q = p + skip + (w - 1 - b)
            for r in range(m):
                vals[boff[s] + b * m + r] = data[q + r] * inv


# The sweeps index with unsigned integers (all offsets are uint64): a signed index makes numba
# emit a negative-index wraparound select on every load, which kept LLVM from vectorising the
# block loops (measured 1.6x slower block products).
# They solve k right-hand sides at once, the rows of y, x (k, n) and tmp (k, m): each factor
# column is read from memory once and reused from cache for the other right-hand sides (the
# sweeps are memory-bound, so two solves together cost little more than one).


@njit(cache=True)
def _unit_lower_solve(y, c0, w, tri, off):
    """y[:, c0:c0+w] <- T^-1 y[:, c0:c0+w] for the supernode's unit lower triangle T (at
    tri[off:])."""
    for b in range(w):
        col = off + b * w
        for j in range(y.shape[0]):
            yj = y[j]
            yb = yj[c0 + b]
            for a in range(b + U1, w):
                yj[c0 + a] -= tri[col + a] * yb


@njit(cache=True, fastmath=True)
def _unit_upper_solve(x, c0, w, tri, off):
    """x[:, c0:c0+w] <- T^-T x[:, c0:c0+w] (the transpose of ``_unit_lower_solve``)."""
    for k in range(U1, w):
        b = w - U1 - k
        col = off + b * w
        for j in range(x.shape[0]):
            xj = x[j]
            acc = xj[c0 + b]
            for a in range(b + U1, w):
                acc -= tri[col + a] * xj[c0 + a]
            xj[c0 + b] = acc


@njit(cache=True, fastmath=True)
def _block_product(vals, p, m, lo, hi, y, c0, w, tmp):
    """tmp[:, lo:hi] = (V[lo:hi] @ y[:, c0:c0+w].T).T, V the column-major (m, w) block at
    vals[p:]."""
    for j in range(y.shape[0]):
        for r in range(lo, hi):
            tmp[j, r] = 0.0
    for b in range(w):  # column by column: contiguous, vectorised
        col = p + b * m
        for j in range(y.shape[0]):
            yb = y[j, c0 + b]
            tj = tmp[j]
            for r in range(lo, hi):
                tj[r] += vals[col + r] * yb


@njit(cache=True, fastmath=True)
def _block_transposed_product(vals, p, m, b0, b1, tmp, y, dinv, x, c0):
    """x[:, c0+b] = y[:, c0+b] dinv[c0+b] - tmp[:, :m] @ V[:, b] for the block columns b in
    [b0, b1)."""
    for b in range(b0, b1):
        col = p + b * m
        for j in range(y.shape[0]):
            tj = tmp[j]
            acc = 0.0
            for r in range(m):
                acc += vals[col + r] * tj[r]
            x[j, c0 + b] = y[j, c0 + b] * dinv[c0 + b] - acc


@njit(cache=True, fastmath=True)
def _forward_block(s, y, starts, widths, roff, rows, boff, vals, toff, tri, n_own, buf, tmp):
    c0, w, r0 = starts[s], widths[s], roff[s]
    m = roff[s + 1] - r0
    _unit_lower_solve(y, c0, w, tri, toff[s])
    _block_product(vals, boff[s], m, U0, m, y, c0, w, tmp)
    for j in range(y.shape[0]):
        for r in range(n_own[s]):
            y[j, rows[r0 + r]] -= tmp[j, r]
        for r in range(n_own[s], m):
            buf[j, rows[r0 + r]] -= tmp[j, r]


@njit(cache=True, fastmath=True)
def _backward_block(s, y, x, dinv, starts, widths, roff, rows, boff, vals, toff, tri, tmp):
    c0, w, r0 = starts[s], widths[s], roff[s]
    m = roff[s + 1] - r0
    for j in range(x.shape[0]):
        for r in range(m):
            tmp[j, r] = x[j, rows[r0 + r]]
    _block_transposed_product(vals, boff[s], m, U0, w, tmp, y, dinv, x, c0)
    _unit_upper_solve(x, c0, w, tri, toff[s])


@njit(cache=True, parallel=True, fastmath=True)
def _solve(b, perm, dinv, starts, widths, roff, rows, boff, vals, toff, tri, n_own, bin_ptr,
           bin_sn, top_sn, top_rows, buf, tmp, y, x, out):  # fmt: skip
    """out (k, n) = A^-1 b for the rows of b (k, n); buf (bins, k, n) zero, tmp (bins, k, m)
    and y, x (k, n) work arrays."""
    n, k = perm.size, b.shape[0]
    for j in range(k):
        for i in range(n):
            y[j, i] = b[j, perm[i]]
    n_bins = bin_ptr.size - 1
    for t in prange(n_bins):
        for q in range(bin_ptr[t], bin_ptr[t + 1]):
            _forward_block(bin_sn[q], y, starts, widths, roff, rows, boff, vals, toff, tri,
                           n_own, buf[t], tmp[t])  # fmt: skip
    for t in range(n_bins):
        for j in range(k):
            for i in top_rows:
                y[j, i] += buf[t, j, i]
                buf[t, j, i] = 0.0
    nb = np.uint64(n_bins)
    for q in range(top_sn.size):  # top supernodes: one at a time, rows split over threads
        s = top_sn[q]
        c0, w, r0, tm = starts[s], widths[s], roff[s], tmp[0]
        m = roff[s + 1] - r0
        _unit_lower_solve(y, c0, w, tri, toff[s])
        for t in prange(n_bins):
            lo, hi = (m * np.uint64(t)) // nb, (m * np.uint64(t + 1)) // nb
            _block_product(vals, boff[s], m, lo, hi, y, c0, w, tm)
            for j in range(k):
                for r in range(lo, hi):
                    y[j, rows[r0 + r]] -= tm[j, r]
    for q in range(top_sn.size - 1, -1, -1):  # columns split over threads
        s = top_sn[q]
        c0, w, r0, tm = starts[s], widths[s], roff[s], tmp[0]
        m = roff[s + 1] - r0
        for j in range(k):
            for r in range(m):
                tm[j, r] = x[j, rows[r0 + r]]
        for t in prange(n_bins):
            b0, b1 = (w * np.uint64(t)) // nb, (w * np.uint64(t + 1)) // nb
            _block_transposed_product(vals, boff[s], m, b0, b1, tm, y, dinv, x, c0)
        _unit_upper_solve(x, c0, w, tri, toff[s])
    for t in prange(n_bins):
        for q in range(bin_ptr[t + 1] - 1, bin_ptr[t] - 1, -1):
            _backward_block(bin_sn[q], y, x, dinv, starts, widths, roff, rows, boff, vals, toff,
                            tri, tmp[t])  # fmt: skip
    for j in range(k):
        for i in range(n):
            out[j, perm[i]] = x[j, i]


def _strict_lower(L: sp.spmatrix) -> sp.csc_matrix:
    """The entries of L below the diagonal (explicit zeros kept), CSC with sorted indices."""
    L = sp.csc_matrix(L)
    if not L.has_sorted_indices:
        L = L.copy()
        L.sort_indices()
    cols = np.repeat(np.arange(L.shape[1]), np.diff(L.indptr))
    keep = L.indices > cols
    indptr = np.r_[0, np.cumsum(np.bincount(cols[keep], minlength=L.shape[1]))]
    return sp.csc_matrix((L.data[keep], L.indices[keep], indptr), shape=L.shape)


def _elimination_tree(indptr: np.ndarray, indices: np.ndarray, skip: int = 0) -> np.ndarray:
    """parent[j] = first row below the diagonal in column j of a sorted CSC factor whose
    columns hold ``skip`` (0 or 1) diagonal entries first; -1 for roots."""
    below = np.flatnonzero(np.diff(indptr) > skip)
    parent = np.full(indptr.size - 1, -1, np.int64)
    parent[below] = indices[indptr[below] + skip]
    return parent


def _unit_lower(L: sp.csc_matrix) -> tuple[sp.csc_matrix, np.ndarray]:
    """(L / diag(L), diag(L)^2): the unit factor and D of A = L L^T = L' D L'^T."""
    diag = L.diagonal()
    unit = sp.csc_matrix(L, copy=True)
    unit.data /= np.repeat(diag, np.diff(unit.indptr))
    return unit, diag**2


class ParallelLDL:
    """Solve A x = b for a fixed factor A = P^T L D L^T P on ``n_threads`` threads.

    L: (n, n) sparse unit lower triangular (diagonal stored or not); d: (n,) diagonal of D;
    perm: (n,) with (P b)[i] = b[perm[i]]. n_threads: work pieces (default: numba's thread
    pool size, :func:`~physanim.fem.numba_threads.work_partitions`).
    strict: L is already CSC with sorted indices and only its strictly lower entries.
    dtype: float64, or float32 to store L's entries in single precision (half the bytes the
    memory-bound sweeps read; the sweeps still accumulate in float64).
    Not re-entrant: one solve at a time per instance (it reuses its work arrays; instances
    made by ``refilled`` share them with their source).
    """

    def __init__(
        self,
        L: sp.spmatrix,
        d: np.ndarray,
        perm: np.ndarray,
        n_threads: int | None = None,
        dtype: type = np.float64,
        strict: bool = False,
    ) -> None:
        Ls = L if strict else _strict_lower(L)
        perm = np.asarray(perm, dtype=np.int64)
        d = np.asarray(d, dtype=np.float64)
        self._q = None
        parent = _elimination_tree(Ls.indptr, Ls.indices)
        if not _is_postordered(parent):
            # a postorder keeps L lower triangular (ancestors stay after descendants)
            self._q = q = _postorder(parent)
            Ls = sp.csc_matrix(Ls[q][:, q])
            Ls.sort_indices()
            perm, d = perm[q], d[q]
            parent = _elimination_tree(Ls.indptr, Ls.indices)
        self._pattern = (
            None
            if strict or not (sp.issparse(L) and L.format == "csc")
            else (L.indptr.copy(), L.indices.copy())
        )
        self._layout(Ls.indptr, Ls.indices, 0, parent, perm, n_threads, dtype)
        self.dinv = 1.0 / d
        self._pack(Ls.data, cholesky=False)

    def _layout(
        self,
        indptr: np.ndarray,
        indices: np.ndarray,
        skip: int,
        parent: np.ndarray,
        perm: np.ndarray,
        n_threads: int | None,
        dtype: type,
    ) -> None:
        """The supernode blocks, their row indices and the tree partition of a postordered
        sorted CSC factor (indptr, indices) whose columns hold ``skip`` diagonal entries
        first, with elimination tree ``parent``; the values are packed by ``_pack``."""
        n = indptr.size - 1
        size = _subtree_sizes(parent)
        self.n = n
        self.perm = perm
        self.dtype = np.dtype(dtype)
        indptr = indptr.astype(np.int64, copy=False)
        # indices stay as given (CHOLMOD's int32): an int64 copy is 8 bytes per entry
        cnt = np.diff(indptr) - skip
        n_bins = work_partitions(n_threads)
        is_top, bin_roots = _partition(parent, cnt + 1, n_bins)

        # fundamental supernodes: j joins j+1 when j+1 is its parent and only child and the
        # patterns agree; never across a bin subtree's root (its parent is in the top)
        n_child = np.bincount(parent[parent >= 0], minlength=n)
        nxt = np.arange(1, n + 1)
        merge = (parent == nxt) & (cnt == np.r_[cnt[1:], 0] + 1)
        merge &= n_child[np.minimum(nxt, n - 1)] == 1
        merge &= ~(~is_top & np.r_[is_top[1:], False])
        starts = np.flatnonzero(np.r_[True, ~merge[:-1]]) if n else np.zeros(0, np.int64)
        widths = np.diff(np.r_[starts, n])
        last = starts + widths - 1
        m = cnt[last]
        roff = np.r_[0, np.cumsum(m)]
        boff = np.r_[0, np.cumsum(m * widths)]
        toff = np.r_[0, np.cumsum(widths * widths)]
        self.rows = np.zeros(roff[-1], np.uint32)  # unsigned: no wraparound check on loads
        _pack_rows(indptr, indices, skip, starts, widths, roff, self.rows)
        self._packing = (indptr, skip, starts, widths, roff, boff, toff)
        u64 = lambda a: np.asarray(a, np.uint64)  # noqa: E731
        self.starts, self.widths = u64(starts), u64(widths)
        self.roff, self.boff, self.toff = u64(roff), u64(boff), u64(toff)

        # supernodes per bin (its subtrees are contiguous column ranges in postorder) and top
        sn_of = np.repeat(np.arange(starts.size), widths)
        self.n_own = m.astype(np.uint64)  # block rows inside its own subtree (top: all)
        bin_sn = []
        for roots in bin_roots:
            ids = []
            for r in sorted(roots):
                s_ids = np.arange(sn_of[r - size[r] + 1], sn_of[r] + 1)
                for s in s_ids:
                    self.n_own[s] = np.searchsorted(self.rows[roff[s] : roff[s + 1]], r + 1)
                ids.append(s_ids)
            bin_sn.append(np.concatenate(ids) if ids else np.zeros(0, np.int64))
        self.bin_ptr = np.r_[0, np.cumsum([b.size for b in bin_sn])].astype(np.int64)
        self.bin_sn = np.concatenate(bin_sn).astype(np.int64)
        self.top_sn = np.flatnonzero(is_top[starts]).astype(np.int64)
        self.top_rows = np.flatnonzero(is_top).astype(np.int64)
        self._n_bins, self._m_max = n_bins, int(m.max(initial=0))
        self._work: dict[int, tuple[np.ndarray, ...]] = {}

    def _pack(self, data: np.ndarray, cholesky: bool) -> None:
        """New ``vals`` and ``tri`` (and ``dinv`` when ``cholesky``) from a factor's values
        ``data`` on the pattern ``_layout`` was given."""
        indptr, skip, starts, widths, roff, boff, toff = self._packing
        self.vals = np.zeros(boff[-1], self.dtype)
        self.tri = np.zeros(toff[-1], self.dtype)
        if cholesky:
            self.dinv = np.empty(self.n)
        _pack_values(indptr, data, skip, cholesky, starts, widths, roff, boff, toff, self.vals,
                     self.tri, self.dinv)  # fmt: skip

    @classmethod
    def from_cholesky(
        cls,
        L: sp.csc_matrix,
        perm: np.ndarray,
        n_threads: int | None = None,
        dtype: type = np.float64,
    ) -> ParallelLDL:
        """Solver of A = P^T L L^T P from a Cholesky factor L (CSC, lower, diagonal first in
        each column, as CHOLMOD gives it); ``refilled_cholesky`` reuses it for other factors
        with L's pattern. The blocks are packed from L's arrays in one compiled pass that
        divides by the diagonal: no unit factor is built (12M entries, 0.1 s on the demo)."""
        L = sp.csc_matrix(L)
        first = L.indptr[:-1]
        if L.nnz and not np.array_equal(L.indices[first], np.arange(L.shape[0])):
            raise ValueError("from_cholesky: L must hold its diagonal first in each column")
        if not L.has_sorted_indices:
            L = L.sorted_indices()
        perm = np.asarray(perm, dtype=np.int64)
        parent = _elimination_tree(L.indptr, L.indices, skip=1)
        if not _is_postordered(parent):  # not CHOLMOD's: reordered by the general path
            unit, d = _unit_lower(L)
            return cls(unit, d, perm, n_threads, dtype)
        out = cls.__new__(cls)
        out._q = None
        out._layout(L.indptr, L.indices, 1, parent, perm, n_threads, dtype)
        out._pack(L.data, cholesky=True)
        # the pattern ``refilled_cholesky`` and ``refilled`` check (L is not modified after)
        out._pattern = (L.indptr, L.indices)
        return out

    def refilled_cholesky(self, L: sp.csc_matrix) -> ParallelLDL:
        """``refilled`` for a Cholesky factor with the pattern of the one this solver was made
        from by ``from_cholesky``: one compiled pass packs the blocks."""
        if not self._diagonal_first or not self._same_pattern(L):
            return self.refilled(*_unit_lower(sp.csc_matrix(L)))
        out = copy.copy(self)
        out._pack(L.data, cholesky=True)
        return out

    def refilled(self, L: sp.csc_matrix, d: np.ndarray) -> ParallelLDL:
        """The solver of another factor with the same CSC pattern as this one's ``L`` (a
        numeric refactorisation after the same symbolic analysis and ordering): the elimination
        tree, its partition and the supernode blocks are reused, only the values are packed."""
        if not self._same_pattern(L):
            raise ValueError("refilled: L must have the CSC pattern of the original factor")
        d = np.asarray(d, dtype=np.float64)
        out = copy.copy(self)
        if self._diagonal_first:  # L holds its (unit) diagonal first in each column
            out.dinv = 1.0 / d
            out._pack(L.data, cholesky=False)
            return out
        Ls = _strict_lower(L)
        if self._q is not None:
            Ls = sp.csc_matrix(Ls[self._q][:, self._q])
            Ls.sort_indices()
            d = d[self._q]
        if not np.array_equal(Ls.indptr, self._packing[0]):
            raise ValueError("refilled: L must have the CSC pattern of the original factor")
        out.dinv = 1.0 / d
        out._pack(Ls.data, cholesky=False)
        return out

    @property
    def _diagonal_first(self) -> bool:
        """Whether the blocks were laid out from a factor holding its diagonal first in each
        column (``from_cholesky``'s direct path), not from its strictly lower part."""
        return self._packing[1] == 1

    def _same_pattern(self, L: sp.spmatrix) -> bool:
        """Whether L is CSC with the pattern of the factor this solver was made from."""
        return (
            self._pattern is not None
            and sp.issparse(L)
            and L.format == "csc"
            and np.array_equal(L.indptr, self._pattern[0])
            and np.array_equal(L.indices, self._pattern[1])
        )

    def _work_arrays(self, k: int) -> tuple[np.ndarray, ...]:
        """buf (bins, k, n) zero, tmp (bins, k, m), y and x (k, n) for k right-hand sides."""
        if k not in self._work:
            n, bins = self.n, self._n_bins
            self._work[k] = (
                np.zeros((bins, k, n)),
                np.zeros((bins, k, self._m_max)),
                np.empty((k, n)),
                np.empty((k, n)),
            )
        return self._work[k]

    def __call__(self, b: np.ndarray) -> np.ndarray:
        """x (n,) or (n, k) for b of the same shape; the k columns in one pass over the
        factor."""
        b = np.asarray(b, dtype=np.float64)
        rows = np.ascontiguousarray(b.T if b.ndim == 2 else b[None])
        out = np.empty_like(rows)
        buf, tmp, y, x = self._work_arrays(rows.shape[0])
        _solve(rows, self.perm, self.dinv, self.starts, self.widths, self.roff, self.rows,
               self.boff, self.vals, self.toff, self.tri, self.n_own, self.bin_ptr, self.bin_sn,
               self.top_sn, self.top_rows, buf, tmp, y, x, out)  # fmt: skip
        return out.T if b.ndim == 2 else out[0]
