"""The mass matrix of a problem: how far it is from symmetric, and whether its symmetrised
diagonal blocks are positive definite.

:func:`symmetry_report` measures the asymmetry of the given M (entrywise, the thresholded
measure, and normwise, information; :class:`SymmetryReport`), :func:`asymmetry_error` is the
refusal of a matrix beyond the limit, :func:`symmetrise` is (M + Mᵀ)/2 as every solver uses
it, and :func:`block_structure_and_definiteness` splits the symmetrised M into the connected
components of its sparsity graph (bodies) and checks each for definiteness
(:class:`BlockStructure`).  :meth:`rfverify.model.problem.Problem.from_arrays` runs them all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .definiteness import DENSE_LIMIT, Definiteness, verify_definite
from ..errors import InvalidProblemError

DENSE_BLOCK_LIMIT = DENSE_LIMIT
"""Diagonal blocks of M up to this size are verified densely (batched by size); larger blocks
by a sparse LDLᵀ (:mod:`rfverify.model.definiteness`)."""


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


BlockStructure = Definiteness
"""Connected components of the sparsity graph of M (bodies, for rigid-body problems) and the
verified facts about each: :class:`rfverify.model.definiteness.Definiteness` (``labels``,
``sizes``, ``count``, the equilibration ``exponents``, ``lam_scaled`` and ``lam_lower``)."""


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


def block_structure_and_definiteness(M_sym: sp.csc_matrix, M_raw: sp.spmatrix | None = None) -> BlockStructure:
    """Split symmetric ``M_sym`` = (M_raw + M_rawᵀ)/2 (rounded to float64) into the connected
    components of its sparsity graph and prove each positive definite, whatever its scale:
    :func:`rfverify.model.definiteness.verify_definite` (the Jacobi-equilibrated block, verified in
    floating point with a-priori rounding-error bounds; an exact rational LDLᵀ for small
    blocks where that cannot decide).  ``M_raw`` None: ``M_sym`` is the data itself.

    Raises
    ------
    InvalidProblemError
        field ``"M"``, index = the failing block and its dof range: "is not positive definite"
        only on an exact proof (a non-positive diagonal entry, a non-positive pivot of the
        exact LDLᵀ, a 2×2 minor or xᵀMx ≤ 0 evaluated exactly), else "could not verify
        positive definiteness" with what was tried.
    """
    check_positive_diagonal(M_sym)
    facts = verify_definite(M_sym, M_raw)
    if facts.failures:
        proven = [f for f in facts.failures if f.proven]
        fail = proven[0] if proven else facts.failures[0]
        _raise_not_pd(fail.block, fail.dofs, fail.reason, fail.proven)
    return facts


def check_positive_diagonal(M: sp.spmatrix):
    diag = M.diagonal()
    bad = np.flatnonzero(~(diag > 0))
    if bad.size:
        j = int(bad[0])
        raise InvalidProblemError(
            "M", f"diagonal entry M[{j},{j}] = {float(diag[j])!r} is not positive, so M is not "
                 f"positive definite ({bad.size} such diagonal entries)",
            index=(j, j), fix="every dof needs a positive mass or inertia")


def _raise_not_pd(block: int, dofs: np.ndarray, detail: str, proven: bool):
    lo, hi = int(dofs.min()), int(dofs.max())
    span = f"dofs {lo}..{hi}" if hi - lo + 1 == dofs.size else f"{dofs.size} dofs from {lo} to {hi}"
    where = f"diagonal block {block} ({span}) of the symmetrised M"
    if proven:
        problem, fix = (f"{where} is {detail}", "check the masses/inertias of that body (a rigid body needs a positive "
                                                 "mass and a positive definite inertia tensor)")
    else:
        problem, fix = (f"{where}: {detail}",
                        "the block is singular or too ill-conditioned to be proven definite in double precision even "
                        "after diagonal scaling: check the masses/inertias of that body (nearly dependent rows of an "
                        "inertia tensor or of an assembled mass matrix)")
    raise InvalidProblemError("M", problem, index=f"block {block}: {span}", fix=fix)
