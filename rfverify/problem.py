"""The global rolling-friction contact problem (FCLIB conventions) and its validation.

A problem with ``n`` contacts and ``m`` degrees of freedom is::

    M v = H r + f          M (m×m) symmetric positive definite,  f ∈ R^m
    u   = Hᵀ v + w         H (m×5n),                             w ∈ R^{5n}
    K* ∋ u ⊥ r ∈ K         per contact i: r_i, u_i ∈ R^5 ordered (N, T1, T2, R1, R2)

with, per contact, ``K_i = {r : ‖r_T‖ ≤ μ_i r_N, ‖r_R‖ ≤ μr_i r_N}`` and its dual
``K*_i = {u : u_N ≥ μ_i ‖u_T‖ + μr_i ‖u_R‖}`` (see DESIGN §1).  Units are whatever the file
uses; rfverify never rescales silently.  All vectors are 1-D float64 arrays; contact-wise
vectors are stored flat (contact i occupies entries ``5i … 5i+4``).

``Problem.M`` is the mass matrix *as given* (real files are slightly unsymmetric, DESIGN §1);
solvers use :attr:`Problem.M_sym` = (M + Mᵀ)/2.  Keeping the raw matrix makes a written file
round-trip bit for bit and lets ``rfverify info`` report the asymmetry of the source data.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .errors import InvalidArgumentError, InvalidProblemError

SPACEDIM = 5
"""Number of components of a rolling-friction contact: (N, T1, T2, R1, R2)."""

DEFAULT_MAX_ASYMMETRY = 1e-2
"""Default limit on the entrywise (scaled) asymmetry max |M_ij − M_ji| / sqrt(M_ii M_jj).

The Siconos Chute file has 2.0e-3 (its inertia blocks are stored with ~1e-6 absolute
rounding); 1e-2 leaves a margin of five while still refusing a matrix that is not meant to be
symmetric.  The measure is invariant under a change of units of the dofs (diagonal scaling)
and local: one wrong entry of a light body counts as much as one of a heavy body.  The
normwise asymmetry ‖M − Mᵀ‖_F/‖M‖_F is reported beside it (in ``rfverify info`` and in the
refusal message) but not thresholded: on matrices whose entries span many decades (assembled
finite-element matrices) it hides every entry of the small-magnitude dofs.  Some real FE files
have entrywise 0.22 but normwise 4e-7; the user judges and passes ``--max-asymmetry``.
"""

DENSE_BLOCK_LIMIT = 400
"""Diagonal blocks of M up to this size are checked for definiteness by batched dense
eigenvalues; larger blocks by a symmetric-ordering LDLᵀ (sparse LU without pivoting)."""


@dataclass(frozen=True, eq=False)
class LocalForm:
    """The local problem a file states, kept beside its global lifting (DESIGN §1.1, §6.1b).

    ``u = W r + q``, ``K* ∋ u ⊥ r ∈ K`` with W (5n × 5n, CSR, every entry exactly the float64
    the file holds, repeated entries summed exactly; a 3-D ``/fclib_local`` W embedded in the
    rolling layout with zero rolling rows and columns) and q (5n,).  The solver works on the
    lifted global problem (M = I, HᵀH ≈ (W + Wᵀ)/2: a solver device); certificates are about
    this problem, with W := (W + Wᵀ)/2 exactly.  ``significant_digits`` is the print precision
    of the source (None: full double); the printed numbers are the data, exactly.
    """

    W: sp.csr_matrix
    q: np.ndarray
    significant_digits: int | None = None

    @property
    def n_rows(self) -> int:
        return int(self.W.shape[0])

    def velocity(self, r, dtype=np.float64) -> np.ndarray:
        """u = (W + Wᵀ)/2 · r + q of the file's problem, summed in longdouble and returned in
        ``dtype`` (float64: what the solver returns and judges for a local file; the proof
        recomputes it exactly)."""
        C = self.W.tocoo()
        r_ld = np.asarray(r, dtype=np.longdouble)
        half = np.longdouble(0.5) * C.data.astype(np.longdouble)
        u = np.zeros(r_ld.size, dtype=np.longdouble)
        np.add.at(u, C.row, half * r_ld[C.col])
        np.add.at(u, C.col, half * r_ld[C.row])
        return np.asarray(u + self.q.astype(np.longdouble), dtype=dtype)


def make_local_form(W, q, significant_digits: int | None = None) -> LocalForm:
    """A frozen :class:`LocalForm` from W (5n × 5n, dense or sparse) and q (5n,)."""
    Wc = sp.csr_matrix(W, dtype=np.float64, copy=True)
    Wc.sum_duplicates()  # readers sum repeated entries exactly before this point
    Wc.eliminate_zeros()
    Wc.sort_indices()
    qf = np.array(q, dtype=np.float64, copy=True)
    if Wc.shape != (qf.size, qf.size):
        raise InvalidProblemError("W", f"has shape {Wc.shape}, expected ({qf.size}, {qf.size}) from q",
                                  fix="W has one row and one column per entry of q")
    return LocalForm(W=_freeze_sparse(Wc), q=_freeze(qf), significant_digits=significant_digits)


@dataclass(frozen=True)
class StoredSolution:
    """A solution (or guess) stored in a problem file: v (m,), u (5n,), r (5n,); any may be None."""

    v: np.ndarray | None = None
    u: np.ndarray | None = None
    r: np.ndarray | None = None



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


@dataclass(frozen=True, eq=False)
class Problem:
    """A validated global rolling-friction contact problem (FCLIB ``fclib_global_rolling``).

    Construct with :meth:`Problem.from_arrays` (which validates) or with
    :func:`rfverify.load`.  Instances are immutable; arrays are read-only.

    Attributes
    ----------
    M : scipy.sparse.csc_matrix, (m, m)
        Mass matrix as given (possibly slightly unsymmetric).  Use :attr:`M_sym` for solving.
    H : scipy.sparse.csc_matrix, (m, 5n)
        Maps contact reactions to generalised forces; Hᵀ maps velocities to contact velocities.
    f : ndarray, (m,)
        Generalised forces (FCLIB sign: ``M v = H r + f``).
    w : ndarray, (5n,)
        Contact-velocity offset (``u = Hᵀ v + w``).
    mu, mu_r : ndarray, (n,)
        Coulomb friction and rolling-resistance coefficients, ≥ 0.
    title, description, math_info : str
        FCLIB ``info`` strings ("" when absent).
    solution : StoredSolution or None
        ``/solution`` of the file; never trusted — see :func:`rfverify.check.check_solution`.
    guesses : tuple of StoredSolution
        ``/guesses`` of the file.
    storage : dict
        Storage format of each matrix in the source (``"triplet"``, ``"csc"``, ``"csr"``,
        ``"dense"``), used as the default when the problem is written back.
    symmetry : SymmetryReport
        Asymmetry of the given M.
    blocks : BlockStructure
        Diagonal blocks of M and their definiteness margins.
    source : str
        Path the problem was read from ("" when built in memory).
    provenance : dict
        JSON-able notes on how the data were obtained (file format, print precision,
        lifting of a local problem, ...).  A problem read from a 3-D FCLIB file has
        ``{"format": "fclib_global" | "fclib_local", "spacedim": 3, "relaxation": ...,
        "mu_r": ..., "symmetrised": ...}`` (and ``"lifted"`` for a local one), see
        :mod:`rfverify.io.fclib3d`.
    native : object or None
        Data of the source file that the internal rolling layout cannot give back exactly
        (the raw W and q of an ``/fclib_local`` problem), so that the problem is written back
        as it was read; None for problems in the rolling layout.
    local : LocalForm or None
        For a problem read from a *local* file (Siconos local ``.dat``, ``/fclib_local``): the
        file's own W and q.  M, H, f, w are then its lifting (a solver device); what is proven
        is the local problem (DESIGN §6).  None for global problems.
    """

    M: sp.csc_matrix
    H: sp.csc_matrix
    f: np.ndarray
    w: np.ndarray
    mu: np.ndarray
    mu_r: np.ndarray
    title: str = ""
    description: str = ""
    math_info: str = ""
    solution: StoredSolution | None = None
    guesses: tuple = ()
    storage: dict = field(default_factory=dict)
    symmetry: SymmetryReport | None = None
    blocks: BlockStructure | None = None
    source: str = ""
    provenance: dict = field(default_factory=dict)
    native: object = field(default=None, repr=False)
    local: LocalForm | None = field(default=None, repr=False)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_arrays(
        cls,
        M,
        H,
        f,
        w,
        mu,
        mu_r,
        *,
        title: str = "",
        description: str = "",
        math_info: str = "",
        solution: StoredSolution | None = None,
        guesses=(),
        storage: dict | None = None,
        max_asymmetry: float = DEFAULT_MAX_ASYMMETRY,
        spacedim: int = SPACEDIM,
        source: str = "",
        provenance: dict | None = None,
    ) -> "Problem":
        """Validate the data and build a :class:`Problem`.

        Parameters
        ----------
        M : array_like or sparse, (m, m)
            Symmetric positive definite (up to ``max_asymmetry``) mass matrix.
        H : array_like or sparse, (m, 5n)
        f : array_like, (m,)
        w : array_like, (5n,)
        mu, mu_r : array_like, (n,)
            Non-negative, finite.
        max_asymmetry : float
            Largest accepted scaled asymmetry max |M_ij − M_ji| / sqrt(M_ii M_jj); the matrix
            is then symmetrised for solving.  Use ``np.inf`` to accept any asymmetry.
        spacedim : int
            Must be 5 (rolling friction); present so that a file's value is checked.

        Raises
        ------
        InvalidProblemError
            naming the field, the first offending index and the fix.
        """
        if spacedim != SPACEDIM:
            raise InvalidProblemError(
                "spacedim",
                f"is {spacedim}, rolling-friction problems have spacedim = {SPACEDIM}",
                fix="use a fclib_global_rolling problem (N, T1, T2, R1, R2 per contact)",
            )
        M = _as_csc("M", M)
        H = _as_csc("H", H)
        f = _as_vector("f", f)
        w = _as_vector("w", w)
        mu = _as_vector("mu", mu)
        mu_r = _as_vector("mu_r", mu_r)

        m = M.shape[0]
        if M.shape[0] != M.shape[1]:
            raise InvalidProblemError("M", f"has shape {M.shape}, must be square",
                                      fix="pass the m×m mass matrix")
        if m == 0:
            raise InvalidProblemError("M", "is empty (m = 0)", fix="a problem needs at least one dof")
        n = mu.size
        if n == 0:
            raise InvalidProblemError("mu", "is empty (no contacts)",
                                      fix="a contact problem needs at least one contact")
        if mu_r.size != n:
            raise InvalidProblemError("mu_r", f"has {mu_r.size} entries but mu has {n}",
                                      fix="give one rolling coefficient per contact")
        if H.shape != (m, SPACEDIM * n):
            raise InvalidProblemError(
                "H", f"has shape {H.shape}, expected (m, 5n) = ({m}, {SPACEDIM * n}) "
                     f"from M ({m}×{m}) and mu ({n} contacts)",
                fix="H must have one row per dof of M and 5 columns per contact")
        if f.size != m:
            raise InvalidProblemError("f", f"has {f.size} entries, expected m = {m}",
                                      fix="f must have one entry per dof of M")
        if w.size != SPACEDIM * n:
            raise InvalidProblemError("w", f"has {w.size} entries, expected 5n = {SPACEDIM * n}",
                                      fix="w must have 5 entries per contact")

        _check_finite_sparse("M", M)
        _check_finite_sparse("H", H)
        for name, vec in (("f", f), ("w", w), ("mu", mu), ("mu_r", mu_r)):
            _check_finite_vector(name, vec)
        for name, vec in (("mu", mu), ("mu_r", mu_r)):
            bad = np.flatnonzero(vec < 0)
            if bad.size:
                raise InvalidProblemError(
                    name, f"is negative ({float(vec[bad[0]])!r}) at contact {bad[0]}"
                          f" ({bad.size} negative in all)",
                    index=int(bad[0]), fix="friction coefficients must be ≥ 0")

        _check_positive_diagonal(M)  # before symmetry: a zero diagonal is not an asymmetry
        symmetry = symmetry_report(M)
        if not symmetry.scaled <= max_asymmetry:
            raise asymmetry_error("M", symmetry, max_asymmetry)

        M_sym = _symmetrise(M)
        M_sym.sort_indices()
        blocks = block_structure_and_definiteness(M_sym)

        if solution is not None:
            solution = _frozen_solution("solution", solution, m, n)
        guesses = tuple(_frozen_solution(f"guesses[{k}]", g, m, n) for k, g in enumerate(guesses))

        problem = cls(
            M=_freeze_sparse(M), H=_freeze_sparse(H), f=_freeze(f), w=_freeze(w),
            mu=_freeze(mu), mu_r=_freeze(mu_r), title=title, description=description,
            math_info=math_info, solution=solution, guesses=guesses,
            storage=dict(storage or {"M": "csc", "H": "csc"}), symmetry=symmetry,
            blocks=blocks, source=source, provenance=dict(provenance or {}),
        )
        object.__setattr__(problem, "M_sym", _freeze_sparse(M_sym))
        return problem

    # ------------------------------------------------------------------ sizes
    @property
    def n_dofs(self) -> int:
        """m, the number of degrees of freedom."""
        return int(self.M.shape[0])

    @property
    def n_contacts(self) -> int:
        """n, the number of contacts."""
        return int(self.mu.size)

    @property
    def spacedim(self) -> int:
        return SPACEDIM

    @cached_property
    def M_sym(self) -> sp.csc_matrix:
        """(M + Mᵀ)/2, the matrix every solver uses (computed at validation)."""
        return _freeze_sparse(_symmetrise(self.M))

    @cached_property
    def contact_free_dofs(self) -> np.ndarray:
        """Indices of dofs in blocks of M that no contact touches (presolve can solve them
        directly: v = M⁻¹ f there)."""
        touched_rows = np.unique(self.H.indices)
        touched_blocks = np.unique(self.blocks.labels[touched_rows])
        free = ~np.isin(self.blocks.labels, touched_blocks)
        return np.flatnonzero(free)

    def with_solution(self, solution: StoredSolution | None) -> "Problem":
        """A copy of this problem with ``solution`` replaced (shapes checked)."""
        if solution is not None:
            solution = _frozen_solution("solution", solution, self.n_dofs, self.n_contacts)
        return dataclasses.replace(self, solution=solution)

    def __repr__(self) -> str:
        return (f"Problem(title={self.title!r}, m={self.n_dofs}, n={self.n_contacts}, "
                f"nnz(M)={self.M.nnz}, nnz(H)={self.H.nnz})")


# ---------------------------------------------------------------------- helpers
def _symmetrise(M: sp.spmatrix) -> sp.csc_matrix:
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
    _check_positive_diagonal(M_sym)
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


def _check_positive_diagonal(M: sp.spmatrix):
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


def _as_csc(name: str, A) -> sp.csc_matrix:
    try:
        if sp.issparse(A):
            A = sp.csc_matrix(A, dtype=np.float64, copy=True)  # never sort the caller's matrix
        else:
            arr = np.asarray(A, dtype=np.float64)
            if arr.ndim != 2:
                raise InvalidProblemError(name, f"has {arr.ndim} dimensions, expected a matrix",
                                          fix="pass a 2-D array or a scipy.sparse matrix")
            A = sp.csc_matrix(arr)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InvalidProblemError):
            raise
        raise InvalidProblemError(name, f"cannot be converted to a float64 matrix ({exc})",
                                  fix="pass numeric data") from None
    A.sum_duplicates()
    A.sort_indices()
    return A


def _as_vector(name: str, x) -> np.ndarray:
    try:
        arr = np.array(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidProblemError(name, f"cannot be converted to a float64 vector ({exc})",
                                  fix="pass numeric data") from None
    if arr.ndim != 1:
        if arr.ndim == 2 and 1 in arr.shape:
            arr = arr.ravel()
        else:
            raise InvalidProblemError(name, f"has shape {arr.shape}, expected a 1-D vector",
                                      fix="pass a flat array")
    return arr


def _check_finite_vector(name: str, x: np.ndarray):
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise InvalidProblemError(name, f"contains a non-finite value ({float(x[bad[0]])!r}) at index "
                                        f"{bad[0]} ({bad.size} in all)",
                                  index=int(bad[0]), fix="remove NaN/Inf from the data")


def _check_finite_sparse(name: str, A: sp.csc_matrix):
    bad = np.flatnonzero(~np.isfinite(A.data))
    if bad.size:
        k = int(bad[0])
        col = int(np.searchsorted(A.indptr, k, side="right") - 1)
        row = int(A.indices[k])
        raise InvalidProblemError(name, f"contains a non-finite value ({float(A.data[k])!r}) at "
                                        f"({row}, {col}) ({bad.size} in all)",
                                  index=(row, col), fix="remove NaN/Inf from the data")


def _frozen_solution(where: str, s: StoredSolution, m: int, n: int) -> StoredSolution:
    """Check shapes/finiteness and return read-only float64 copies (no aliasing of inputs)."""
    out = {}
    for name, arr, size in (("v", s.v, m), ("u", s.u, SPACEDIM * n), ("r", s.r, SPACEDIM * n)):
        if arr is None:
            out[name] = None
            continue
        if np.ndim(arr) != 1 or np.size(arr) != size:
            raise InvalidProblemError(f"{where}.{name}", f"has shape {np.shape(arr)}, expected ({size},)",
                                      fix="store one value per dof (v) or 5 per contact (u, r)")
        vec = _as_vector(f"{where}.{name}", arr)
        _check_finite_vector(f"{where}.{name}", vec)
        out[name] = _freeze(vec)
    return StoredSolution(**out)


def _freeze(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


def _freeze_sparse(A: sp.csc_matrix) -> sp.csc_matrix:
    A = sp.csc_matrix(A, copy=True)
    for arr in (A.data, A.indices, A.indptr):
        arr.setflags(write=False)
    return A


def require_problem(obj, argument: str = "problem"):
    """Refuse anything but a :class:`rfverify.Problem` with an :class:`InvalidArgumentError`."""
    if not isinstance(obj, Problem):
        raise InvalidArgumentError(
            argument, f"expected an rfverify.Problem, got {type(obj).__name__}",
            fix="pass the result of rfverify.load(path) or rfverify.Problem.from_arrays(...)")
    return obj
