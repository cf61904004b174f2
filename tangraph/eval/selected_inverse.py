"""Entries of the inverse of a sparse symmetric positive definite matrix, without the inverse.

The bound with the map's error needs the 2 x 2 position block of every ping in the inverse of
a sparse information matrix of thousands of unknowns; the inverse itself is dense. The LDL^T
factor (:func:`factor`, in a fill-reducing order) and the Takahashi recurrence (Takahashi,
Fagan & Chin 1973; Erisman & Tinney 1975) give every entry of the inverse on the factor's
pattern (:func:`selected_inverse`) for about the cost of the factorisation:

    ``Z = D^-1 L^-1 + (I - L^T) Z``,  so  ``Z_ij = delta_ij / D_j - sum_{k > j} Z_ik L_kj``,

whose terms are all on the pattern of the factor (which is closed under it: the factor here is
symbolic, every entry the elimination can fill is stored even where it is numerically zero).
Entries of the inverse that the matrix holds (explicit zeros included) are on that pattern.

The order is SuperLU's minimum degree on ``A + A^T`` (:func:`fill_reducing_order`); the
factorisation is Davis's up-looking LDL^T (Davis 2005, "Algorithm 849"), in numba.
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np
from scipy import sparse
from scipy.sparse.linalg import splu

from tangraph.errors import TangraphError

__all__ = ["SparseFactor", "factor", "fill_reducing_order", "inverse_entries", "selected_inverse"]

_jit = numba.njit(cache=True, nogil=True)


@dataclasses.dataclass(frozen=True, eq=False)
class SparseFactor:
    """``P A P^T = L D L^T``: ``order`` the permutation (row ``i`` of ``P A P^T`` is row
    ``order[i]`` of ``A``), ``L`` unit lower triangular in CSC without its diagonal (``indptr``,
    ``indices`` sorted in each column, ``data``) and ``d`` the diagonal of ``D``."""

    order: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    data: np.ndarray
    d: np.ndarray

    @property
    def n(self) -> int:
        return int(self.d.size)


def fill_reducing_order(a) -> np.ndarray:
    """A symmetric fill-reducing order of ``a``: SuperLU's minimum degree on ``A + A^T``
    (the column order of its symmetric-mode factorisation)."""
    lu = splu(sparse.csc_array(a), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
              options={"SymmetricMode": True})
    order = np.empty(lu.perm_c.size, dtype=np.int64)
    order[lu.perm_c] = np.arange(lu.perm_c.size)
    return order


def factor(a, order: np.ndarray) -> SparseFactor:
    """The LDL^T factor of the symmetric positive definite ``a`` in the order ``order`` (its
    pattern the symbolic one of ``a``'s stored entries, explicit zeros included).

    Raises
    ------
    TangraphError
        A pivot is not positive (``a`` is not positive definite).
    """
    order = np.asarray(order, dtype=np.int64)
    upper = sparse.triu(sparse.csc_array(a)[order][:, order], format="csc")
    upper.sort_indices()
    n = upper.shape[0]
    indptr = upper.indptr.astype(np.int64)
    indices = upper.indices.astype(np.int64)
    parent, counts = _symbolic(n, indptr, indices)
    lp = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=lp[1:])
    li = np.empty(lp[-1], dtype=np.int64)
    lx = np.empty(lp[-1])
    d = np.empty(n)
    bad = _numeric(n, indptr, indices, upper.data.astype(np.float64), lp, parent, li, lx, d)
    if bad >= 0:
        raise TangraphError(f"selected_inverse: the matrix is not positive definite (pivot {bad} "
                            f"of {n} is {d[bad]:g})")
    return SparseFactor(order, lp, li, lx, d)


def selected_inverse(f: SparseFactor, first: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of ``P A P^T`` on the factor's pattern: its diagonal (n,) and its entries
    below the diagonal (parallel to ``f.data``), in columns ``first`` to ``n - 1`` (the trailing
    block needs no other; columns before ``first`` are left at zero)."""
    z_diag = np.zeros(f.n)
    z_low = np.zeros(f.data.size)
    _takahashi(f.n, f.indptr, f.indices, f.data, f.d, int(first), z_diag, z_low)
    return z_diag, z_low


def inverse_entries(f: SparseFactor, z: tuple[np.ndarray, np.ndarray], rows: np.ndarray,
                    cols: np.ndarray) -> np.ndarray:
    """Entries ``(A^-1)[rows, cols]`` from the selected inverse ``z`` of :func:`selected_inverse`.

    Raises
    ------
    TangraphError
        An entry is not on the factor's pattern (the matrix had no entry there).
    """
    where = np.empty(f.n, dtype=np.int64)
    where[f.order] = np.arange(f.n)
    i, j = where[np.asarray(rows)], where[np.asarray(cols)]
    lo, hi = np.minimum(i, j), np.maximum(i, j)
    out = np.empty(lo.shape)
    flat = _lookup(f.indptr, f.indices, z[0], z[1], lo.ravel(), hi.ravel())
    if np.any(np.isnan(flat)):
        raise TangraphError("selected_inverse: an entry asked for is not on the factor's pattern")
    out[...] = flat.reshape(lo.shape)
    return out


@_jit
def _symbolic(n, ap, ai):  # pragma: no cover - compiled
    """Elimination tree and column counts of L from the upper triangle (column k: rows <= k)."""
    parent = np.full(n, -1, dtype=np.int64)
    flag = np.empty(n, dtype=np.int64)
    counts = np.zeros(n, dtype=np.int64)
    for k in range(n):
        flag[k] = k
        for p in range(ap[k], ap[k + 1]):
            i = ai[p]
            while i < k and flag[i] != k:
                if parent[i] == -1:
                    parent[i] = k
                counts[i] += 1
                flag[i] = k
                i = parent[i]
    return parent, counts


@_jit
def _numeric(n, ap, ai, ax, lp, parent, li, lx, d):  # pragma: no cover - compiled
    """Up-looking LDL^T: row k of L by a sparse triangular solve along the elimination tree.
    Returns -1, or the first pivot that is not positive."""
    y = np.zeros(n)
    pattern = np.empty(n, dtype=np.int64)
    flag = np.empty(n, dtype=np.int64)
    filled = np.zeros(n, dtype=np.int64)
    for k in range(n):
        top = n
        flag[k] = k
        for p in range(ap[k], ap[k + 1]):
            i = ai[p]
            if i > k:
                continue
            y[i] += ax[p]
            length = 0
            while flag[i] != k:
                pattern[length] = i
                length += 1
                flag[i] = k
                i = parent[i]
            while length > 0:
                top -= 1
                length -= 1
                pattern[top] = pattern[length]
        d[k] = y[k]
        y[k] = 0.0
        for t in range(top, n):
            i = pattern[t]
            yi = y[i]
            y[i] = 0.0
            end = lp[i] + filled[i]
            for p in range(lp[i], end):
                y[li[p]] -= lx[p] * yi
            lki = yi / d[i]
            d[k] -= lki * yi
            li[end] = k
            lx[end] = lki
            filled[i] += 1
        if not d[k] > 0.0:
            return k
    return -1


@_jit
def _takahashi(n, lp, li, lx, d, first, z_diag, z_low):  # pragma: no cover - compiled
    """``Z_ij = delta_ij / D_j - sum_{k > j} Z_ik L_kj`` for the columns j >= first, from the last."""
    slot = np.full(n, -1, dtype=np.int64)
    acc = np.zeros(n)
    for j in range(n - 1, first - 1, -1):
        start, stop = lp[j], lp[j + 1]
        for p in range(start, stop):
            slot[li[p]] = p
            acc[p - start] = 0.0
        for q in range(start, stop):
            k = li[q]
            lq = lx[q]
            acc[q - start] += z_diag[k] * lq
            for p in range(lp[k], lp[k + 1]):  # Z_rk, r > k: both r and k in column j
                s = slot[li[p]]
                if s >= 0:
                    acc[s - start] += z_low[p] * lq
                    acc[q - start] += z_low[p] * lx[s]
        total = 0.0
        for p in range(start, stop):
            z_low[p] = -acc[p - start]
            total += lx[p] * z_low[p]
            slot[li[p]] = -1
        z_diag[j] = 1.0 / d[j] - total


@_jit
def _lookup(lp, li, z_diag, z_low, lo, hi):  # pragma: no cover - compiled
    out = np.empty(lo.size)
    for t in range(lo.size):
        j, i = lo[t], hi[t]
        if i == j:
            out[t] = z_diag[j]
            continue
        a, b = lp[j], lp[j + 1]
        while a < b:  # binary search of row i in column j
            mid = (a + b) // 2
            if li[mid] < i:
                a = mid + 1
            else:
                b = mid
        out[t] = z_low[a] if a < lp[j + 1] and li[a] == i else np.nan
    return out
