"""Cholesky factors of a symmetric positive definite matrix in gmpy2 ``mpfr``, in a given
fill-reducing order: the engines of the multiple-precision tail's Newton solve
(:mod:`.wide_factor`), which know nothing of contacts, masses or H̃.

:class:`OrderedPattern` fixes the matrix's sparsity pattern, its order and the storage of
its values; an engine (the :class:`WideCholesky` interface) factors values on it and solves
with the factor.  :class:`SparseWideCholesky` is the tail's (left-looking, memory
O(nnz(L))); :class:`DenseWideCholesky` (an m × m array) is the reference it is tested
against.  Both run the same multiply-subtract pairs in the same sequence for every entry of
L, so their factors and solves agree number for number.  Every operation rounds to the
precision of the caller's gmpy2 context."""

from __future__ import annotations

from typing import Protocol

import gmpy2
import numpy as np
import scipy.sparse as sp

from .ldl import numeric_ldl, symbolic_ldl, ldl_workspace
from .wide_data import dot, zeros


class OrderedPattern:
    """The pattern of a symmetric m × m matrix S, ordered: the engines factor P S Pᵀ with
    (P S Pᵀ)[i, j] = S[order[i], order[j]].  ``pattern`` is any scipy sparse matrix whose
    nonzeros (of either triangle) cover S's; the diagonal is always included.

    The storage convention of the values an engine factors: a 1-D object array of mpfr, the
    lower triangle of P S Pᵀ (diagonal included) in CSC, ``values[indptr[j]:indptr[j + 1]]``
    the entries of column j at the rows ``indices[indptr[j]:indptr[j + 1]]`` (ascending).
    :meth:`slots` maps entries of S to their positions there."""

    def __init__(self, pattern: sp.spmatrix, order: np.ndarray):
        m = pattern.shape[0]
        self.m = m
        self.order = np.asarray(order, dtype=np.int64)
        self.inverse = np.empty_like(self.order)
        self.inverse[self.order] = np.arange(m)
        full = (abs(pattern) + abs(pattern.T) + sp.identity(m, format="csc")).tocsc()
        full = full[self.order][:, self.order].tocsc()
        upper = sp.triu(full, format="csc")
        upper.sort_indices()
        self.upper_indptr, self.upper_indices = upper.indptr.astype(np.int64), upper.indices.astype(np.int64)
        self.parent, self.column_pointers = symbolic_ldl(m, self.upper_indptr, self.upper_indices)
        lower = sp.tril(full, format="csc")
        lower.sort_indices()
        self.indptr, self.indices = lower.indptr.astype(np.int64), lower.indices.astype(np.int64)
        self._keys = np.repeat(np.arange(m, dtype=np.int64), np.diff(self.indptr)) * m + self.indices

    @property
    def ops(self) -> float:
        """The cost of a factorisation in this order, in multiply-subtract pairs: Σ c_j² over
        the counts c_j of the strictly lower entries of each column of L."""
        counts = np.diff(self.column_pointers).astype(np.float64)
        return float(np.sum(counts * counts))

    def slots(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Positions in the values array of the entries S[rows[k], cols[k]] (S's own numbering,
        each in the pattern), or −1 where the entry falls in the strict upper triangle of
        P S Pᵀ (its mirror image carries it)."""
        r, c = self.inverse[np.asarray(rows, dtype=np.int64)], self.inverse[np.asarray(cols, dtype=np.int64)]
        out = np.full(r.shape, -1, dtype=np.int64)
        lower = r >= c
        out[lower] = np.searchsorted(self._keys, c[lower] * self.m + r[lower])
        return out


class WideCholesky(Protocol):
    """An mpfr Cholesky engine on an :class:`OrderedPattern` (it is constructed from one).

    ``factor(values)`` factors P S Pᵀ = L Lᵀ from S's values in the pattern's storage
    convention (length nnz of the lower triangle, mpfr); False if a pivot is not positive
    (the factor is then unusable).  ``solve(b)`` returns x with S x = b, b and x (m,) mpfr
    object arrays in S's own numbering.  ``kind`` names the engine in the form's name."""

    kind: str

    def factor(self, values: np.ndarray) -> bool: ...

    def solve(self, b: np.ndarray) -> np.ndarray: ...


class DenseWideCholesky:
    """The factor in the lower triangle of a dense m × m mpfr array, column by column, each
    pivot column updating one target column at a time and skipping exact zeros: the
    reference the sparse engine is tested against (memory m², O(m³) operations at worst)."""

    kind = "dense"

    def __init__(self, pattern: OrderedPattern):
        self.pattern = pattern
        self.L = None

    def factor(self, values: np.ndarray) -> bool:
        p, m = self.pattern, self.pattern.m
        L = zeros(m * m).reshape(m, m)
        L[p.indices, np.repeat(np.arange(m), np.diff(p.indptr))] = values
        for j in range(m):
            piv = L[j, j]
            if not piv > 0:
                return False
            piv = gmpy2.sqrt(piv)
            L[j, j] = piv
            rows = j + 1 + np.flatnonzero((L[j + 1:, j] != 0).astype(bool))
            if rows.size:
                col = L[rows, j] / piv
                L[rows, j] = col
                # the lower triangle only, one target column at a time (3× faster than the
                # full square update on a 600-dof Lattice; the upper triangle is never read)
                for t, target in enumerate(rows):
                    L[rows[t:], target] -= col[t:] * col[t]
        self.L = L
        return True

    def solve(self, b: np.ndarray) -> np.ndarray:
        L, order = self.L, self.pattern.order
        y = b[order]
        for j in range(L.shape[0]):
            y[j] = y[j] / L[j, j]
            y[j + 1:] -= L[j + 1:, j] * y[j]
        for j in range(L.shape[0] - 1, -1, -1):
            y[j] = (y[j] - dot(L[j + 1:, j], y[j + 1:])) / L[j, j]
        x = np.empty_like(y)
        x[order] = y
        return x


class SparseWideCholesky:
    """The factor on the symbolic structure of L: its strictly lower entries ``Lx`` in CSC
    (``Lp``, ``Li``, rows ascending) and its diagonal ``Ld`` — memory nnz(L) + m mpfr
    numbers, so the tail has no limit in dofs, only in its cost (:attr:`OrderedPattern.ops`).

    The factorisation is left-looking by columns: column j of L gathers the updates of the
    columns k that have an entry in row j (one vectorised object-array operation per entry of
    L, the same count of Python-level steps as the dense engine's per-target updates), then
    is scaled by its pivot √d_j.  A solve is two sweeps over the columns."""

    kind = "sparse"

    def __init__(self, pattern: OrderedPattern):
        self.pattern = pattern
        m = pattern.m
        Ap, Ai, Lp = pattern.upper_indptr, pattern.upper_indices, pattern.column_pointers
        # the structure itself from the double-double LDLᵀ of a strictly diagonally dominant
        # matrix on the pattern (its kernel, compiled for the double-double phase already,
        # writes every structural entry; no pivot can fail)
        dominant = np.where(Ai == np.repeat(np.arange(m), np.diff(Ap)), float(m + 1), 1.0)
        nnz = int(Lp[-1])
        Li = np.zeros(nnz, dtype=np.int64)
        if numeric_ldl(m, Ap, Ai, dominant, np.zeros(Ai.size), Lp, pattern.parent, Li, np.zeros(nnz), np.zeros(nnz),
                       np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m), *ldl_workspace(m),
                       np.zeros(1, dtype=np.int64)) >= 0:
            raise AssertionError("a diagonally dominant matrix lost a pivot")
        self.Lp, self.Li = Lp, Li
        # row j of L: the columns k < j with an entry there, each with the offset of that entry
        # in column k (the column's entries at rows ≥ j start there: rows ascend)
        cols_of = np.repeat(np.arange(m, dtype=np.int64), np.diff(Lp))
        by_row = np.lexsort((cols_of, Li))
        self.row_ptr = np.concatenate(([0], np.cumsum(np.bincount(Li, minlength=m)))).astype(np.int64)
        self.row_cols = cols_of[by_row]
        self.row_entry = by_row.astype(np.int64)  # index into Li / Lx
        self.Lx = None
        self.Ld = None

    def factor(self, values: np.ndarray) -> bool:
        p, m = self.pattern, self.pattern.m
        Lp, Li = self.Lp, self.Li
        Lx = np.empty(Li.size, dtype=object)
        Ld = np.empty(m, dtype=object)
        w = zeros(m)  # the column being built, scattered by row
        for j in range(m):
            a, b = p.indptr[j], p.indptr[j + 1]
            w[p.indices[a:b]] = values[a:b]
            for t in range(self.row_ptr[j], self.row_ptr[j + 1]):
                e = self.row_entry[t]  # L[j, k]: the first entry of column k at a row ≥ j
                end = Lp[self.row_cols[t] + 1]
                w[Li[e:end]] -= Lx[e:end] * Lx[e]
            piv = w[j]
            if not piv > 0:
                return False
            piv = gmpy2.sqrt(piv)
            Ld[j] = piv
            rows = Li[Lp[j]:Lp[j + 1]]
            Lx[Lp[j]:Lp[j + 1]] = w[rows] / piv
            w[j] = gmpy2.mpfr(0)
            w[rows] = gmpy2.mpfr(0)
        self.Lx, self.Ld = Lx, Ld
        return True

    def solve(self, b: np.ndarray) -> np.ndarray:
        Lp, Li, Lx, Ld, order = self.Lp, self.Li, self.Lx, self.Ld, self.pattern.order
        y = b[order]
        for j in range(Ld.size):
            y[j] = y[j] / Ld[j]
            a, e = Lp[j], Lp[j + 1]
            if e > a:
                y[Li[a:e]] -= Lx[a:e] * y[j]
        for j in range(Ld.size - 1, -1, -1):
            a, e = Lp[j], Lp[j + 1]
            y[j] = (y[j] - dot(Lx[a:e], y[Li[a:e]])) / Ld[j]
        x = np.empty_like(y)
        x[order] = y
        return x
