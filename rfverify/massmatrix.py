"""The mass matrix of a problem: how far it is from symmetric, and whether its symmetrised
diagonal blocks are positive definite.

:func:`symmetry_report` measures the asymmetry of the given M (entrywise, the thresholded
measure, and normwise, information; :class:`SymmetryReport`), :func:`asymmetry_error` is the
refusal of a matrix beyond the limit, :func:`symmetrise` is (M + Mᵀ)/2 as every solver uses
it, and :func:`block_structure_and_definiteness` splits the symmetrised M into the connected
components of its sparsity graph (bodies) and checks each for definiteness
(:class:`BlockStructure`).  :meth:`rfverify.problem.Problem.from_arrays` runs them all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .errors import InvalidProblemError

DENSE_BLOCK_LIMIT = 400
"""Diagonal blocks of M up to this size are checked for definiteness by batched dense
eigenvalues; larger blocks by a symmetric-ordering LDLᵀ (sparse LU without pivoting)."""


@dataclass(frozen=True)
class SymmetryReport:
    """How far the given M is from symmetric.

    ``scaled`` = max |M_ij − M_ji| / sqrt(M_ii M_jj) (entrywise: unit-invariant, the thresholded
    measure), attained at ``(row, col)``; ``frobenius`` = ‖M − Mᵀ‖_F / ‖M‖_F (normwise,
    information).
    """

    scaled: float
    frobenius: float
    row: int | None
    col: int | None

    @property
    def entrywise(self) -> float:
        """Alias of ``scaled``: max |M_ij − M_ji| / sqrt(M_ii M_jj)."""
        return self.scaled

    @property
    def normwise(self) -> float:
        """Alias of ``frobenius``: ‖M − Mᵀ‖_F / ‖M‖_F."""
        return self.frobenius

    def as_dict(self, matrix: str = "M") -> dict:
        """JSON-able: both measures, where the entrywise one is attained, and whether the
        matrix was symmetrised ((A + Aᵀ)/2 differs from A)."""
        return {"matrix": matrix, "entrywise": self.scaled, "normwise": self.frobenius,
                "at": None if self.row is None else [self.row, self.col],
                "symmetrised": bool(self.scaled > 0)}

    def describe(self, matrix: str = "M") -> str:
        """One line: what was symmetrised and both measures (``info``, solution files)."""
        if not self.scaled > 0:
            return f"{matrix} is exactly symmetric: nothing symmetrised"
        at = "" if self.row is None else f" at ({self.row}, {self.col})"
        return (f"{matrix} symmetrised as ({matrix} + {matrix}^T)/2; entrywise asymmetry "
                f"max|{matrix}_ij - {matrix}_ji|/sqrt({matrix}_ii {matrix}_jj) = {self.scaled:.3g}{at}, "
                f"normwise ||{matrix} - {matrix}^T||_F/||{matrix}||_F = {self.frobenius:.3g}")


def asymmetry_error(matrix: str, report: SymmetryReport, max_asymmetry: float) -> InvalidProblemError:
    """The refusal of a matrix whose entrywise asymmetry exceeds ``max_asymmetry``: both
    measures, so the user can judge, and the option value that would accept it."""
    suggest = _round_up_2(report.scaled)
    return InvalidProblemError(
        matrix,
        f"is not symmetric: entrywise asymmetry max|{matrix}_ij - {matrix}_ji|/sqrt({matrix}_ii "
        f"{matrix}_jj) = {report.scaled:.3g} > max_asymmetry = {max_asymmetry:.3g} (the thresholded "
        f"measure); normwise ||{matrix} - {matrix}^T||_F/||{matrix}||_F = {report.frobenius:.3g}",
        index=None if report.row is None else (report.row, report.col),
        fix=f"if the difference is rounding in the source data (a small normwise figure suggests "
            f"so), accept it and solve with ({matrix} + {matrix}^T)/2: --max-asymmetry {suggest} "
            f"(Python: max_asymmetry={suggest}); otherwise check the matrix")


def _round_up_2(x: float) -> str:
    """``x`` rounded up to two significant digits, as text (a limit that accepts ``x``)."""
    if not np.isfinite(x):
        return "inf"
    if x <= 0:
        return "0"
    text = f"{x:.2g}"
    step = 10.0 ** (np.floor(np.log10(float(text))) - 1)
    while float(text) < x:
        text = f"{float(text) + step:.2g}"
    return text


@dataclass(frozen=True)
class BlockStructure:
    """Connected components of the sparsity graph of M (bodies, for rigid-body problems).

    ``labels[j]`` is the block of dof j; ``sizes[b]`` the number of dofs of block b;
    ``min_eigenvalues[b]`` the smallest eigenvalue of the symmetrised block (NaN when the
    block was checked by factorisation only, in which case ``min_pivots[b]`` is set).
    """

    labels: np.ndarray
    sizes: np.ndarray
    min_eigenvalues: np.ndarray
    min_pivots: np.ndarray

    @property
    def count(self) -> int:
        return int(self.sizes.size)



def symmetrise(M: sp.spmatrix) -> sp.csc_matrix:
    """(M + Mᵀ)/2 computed as M/2 + Mᵀ/2: the same value (halving is exact), but entries near
    1e308 do not overflow to inf."""
    return (M * 0.5 + M.T * 0.5).tocsc()


def symmetry_report(M: sp.spmatrix) -> SymmetryReport:
    """Measure the asymmetry of a square sparse matrix (see :class:`SymmetryReport`)."""
    M = sp.csc_matrix(M)
    A = (M - M.T).tocoo()
    A.eliminate_zeros()
    # Frobenius norms of pre-scaled data: squares of entries near 1e154 would overflow.
    big = float(np.abs(M.data).max(initial=0.0))
    normM = sp.linalg.norm(M / big) if big > 0 else 0.0
    frob = float(sp.linalg.norm(A / big) / normM) if normM > 0 else 0.0
    if A.nnz == 0:
        return SymmetryReport(0.0, frob, None, None)
    # sqrt(d_i)·sqrt(d_j), not sqrt(d_i d_j): the product under/overflows at extreme scales.
    d = np.sqrt(np.abs(M.diagonal()))
    scale = d[A.row] * d[A.col]
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(scale > 0, np.abs(A.data) / scale, np.inf)
    k = int(np.argmax(rel))
    return SymmetryReport(float(rel[k]), frob, int(A.row[k]), int(A.col[k]))


def block_structure_and_definiteness(M_sym: sp.csc_matrix) -> BlockStructure:
    """Split symmetric ``M_sym`` into the connected components of its sparsity graph and check
    each for positive definiteness.

    Small blocks (≤ DENSE_BLOCK_LIMIT dofs) are grouped by size and their eigenvalues computed
    in one batched call per size (rigid bodies give thousands of 6×6 blocks); large blocks are
    factored by sparse LU with a symmetric fill-reducing ordering and no off-diagonal
    pivoting, which is an LDLᵀ factorisation whose pivots are all positive exactly when the
    block is positive definite (Sylvester).

    Raises
    ------
    InvalidProblemError
        field ``"M"``, index = the failing block and its dof range.
    """
    check_positive_diagonal(M_sym)
    n_blocks, labels = connected_components(M_sym, directed=False)
    sizes = np.bincount(labels, minlength=n_blocks)
    min_eig = np.full(n_blocks, np.nan)
    min_piv = np.full(n_blocks, np.nan)
    order = np.argsort(labels, kind="stable")  # dofs grouped by block, increasing within
    starts = np.concatenate(([0], np.cumsum(sizes)))
    csr = M_sym.tocsr()
    for size in np.unique(sizes):
        ids = np.flatnonzero(sizes == size)
        if size <= DENSE_BLOCK_LIMIT:
            # Gather every block of this size into one (count, size, size) stack.
            dofs = order[starts[ids][:, None] + np.arange(size)[None, :]]
            stack = _gather_blocks(csr, dofs)
            eig = np.linalg.eigvalsh(stack)[:, 0]
            min_eig[ids] = eig
            # Relative threshold: an eigenvalue below eps·‖block‖ is zero to working accuracy.
            norms = np.abs(stack).max(axis=(1, 2))
            fail = np.flatnonzero(~(eig > 8 * np.finfo(float).eps * size * norms))
            if fail.size:
                b = int(ids[fail[0]])
                _raise_not_pd(b, order[starts[b]:starts[b + 1]], f"smallest eigenvalue "
                              f"{eig[fail[0]]:.3e} (block norm {norms[fail[0]]:.3e})")
        else:
            for b in ids:
                dofs = order[starts[b]:starts[b + 1]]
                block = csr[dofs][:, dofs].tocsc()
                pivots = _ldl_pivots(block)
                min_piv[b] = pivots.min()
                if not pivots.min() > 8 * np.finfo(float).eps * size * abs(block).max():
                    _raise_not_pd(int(b), dofs, f"LDLᵀ pivot {pivots.min():.3e}")
    return BlockStructure(labels=labels, sizes=sizes, min_eigenvalues=min_eig, min_pivots=min_piv)


def check_positive_diagonal(M: sp.spmatrix):
    diag = M.diagonal()
    bad = np.flatnonzero(~(diag > 0))
    if bad.size:
        j = int(bad[0])
        raise InvalidProblemError(
            "M", f"diagonal entry M[{j},{j}] = {float(diag[j])!r} is not positive, so M is not "
                 f"positive definite ({bad.size} such diagonal entries)",
            index=(j, j), fix="every dof needs a positive mass or inertia")


def _gather_blocks(csr: sp.csr_matrix, dofs: np.ndarray) -> np.ndarray:
    """Dense (count, s, s) stack of the diagonal blocks M[dofs[b]][:, dofs[b]]."""
    count, s = dofs.shape
    rows = dofs.ravel()
    sub = csr[rows].tocoo()  # rows of all blocks, all columns
    # Position of each column inside its block: only entries whose column is in the same
    # block as the row survive (blocks are connected components, so all do).
    pos_in_block = np.empty(csr.shape[1], dtype=np.int64)
    pos_in_block[dofs.ravel()] = np.tile(np.arange(s), count)
    stack = np.zeros((count, s, s))
    blk = sub.row // s
    stack[blk, sub.row % s, pos_in_block[sub.col]] = sub.data
    return stack


def _ldl_pivots(block: sp.csc_matrix) -> np.ndarray:
    from scipy.sparse.linalg import splu

    try:
        lu = splu(block, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                  options={"SymmetricMode": True})
    except RuntimeError:  # exactly singular
        return np.array([0.0])
    if np.any(lu.perm_r != lu.perm_c):
        # SuperLU pivoted off the diagonal after all: fall back to the dense test.
        return np.linalg.eigvalsh(block.toarray())
    return lu.U.diagonal()


def _raise_not_pd(block: int, dofs: np.ndarray, detail: str):
    lo, hi = int(dofs.min()), int(dofs.max())
    span = f"dofs {lo}..{hi}" if hi - lo + 1 == dofs.size else f"{dofs.size} dofs from {lo} to {hi}"
    raise InvalidProblemError(
        "M", f"diagonal block {block} ({span}) of the symmetrised M is not positive definite: "
             f"{detail}",
        index=f"block {block}: {span}",
        fix="check the masses/inertias of that body (a rigid body needs a positive mass and "
            "a positive definite inertia tensor)")
