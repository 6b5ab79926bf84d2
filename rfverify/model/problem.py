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

The checks of M (symmetry, definiteness of its diagonal blocks) are :mod:`rfverify.model.massmatrix`,
the conversion and finiteness checks of every array :mod:`rfverify.model._arrays`; their public names
are importable from here as before.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from ._arrays import as_csc, as_vector, check_finite_sparse, check_finite_vector, freeze, freeze_sparse
from .directed import bound_text
from ..errors import InvalidArgumentError, InvalidProblemError
from .massmatrix import (DENSE_BLOCK_LIMIT, BlockStructure, SymmetryReport, asymmetry_error,
                         block_structure_and_definiteness, check_positive_diagonal, symmetrise,
                         symmetry_report)

__all__ = ["SPACEDIM", "DEFAULT_MAX_ASYMMETRY", "DENSE_BLOCK_LIMIT", "Problem", "StoredSolution",
           "LocalForm", "make_local_form", "require_problem", "SymmetryReport", "BlockStructure",
           "symmetry_report", "asymmetry_error", "block_structure_and_definiteness"]

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
    return LocalForm(W=freeze_sparse(Wc), q=freeze(qf), significant_digits=significant_digits)


PSD_SHIFT_MARK = "D ≥ 0 diagonal"
"""How a statement names the diagonal D added to a local W that is not PSD as stored
(:func:`rfverify.proof.psd_shift.shift_to_psd`); a verdict that finds it calls the matrix W + D."""


@dataclass(frozen=True)
class StoredSolution:
    """A solution (or guess) stored in a problem file: v (m,), u (5n,), r (5n,); any may be None."""

    v: np.ndarray | None = None
    u: np.ndarray | None = None
    r: np.ndarray | None = None


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
        ``/solution`` of the file; never trusted — see :func:`rfverify.model.check.check_solution`.
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
    equations : {"symmetrised", "stored"}
        Which equations every solver, criterion and proof of this problem object judges:
        ``"symmetrised"`` (default, the field's convention: Siconos' GRFC3D_IPM and FCLIB's
        format take M symmetric) poses M v = H r + f with M := (M + Mᵀ)/2 (W := (W + Wᵀ)/2 for
        a local file); ``"stored"`` poses them with M (W) exactly as stored.  The two differ
        only where the stored matrix is unsymmetric (:attr:`matrix_is_symmetric`); factorisations
        always use the symmetric part.  :meth:`stored_equations` gives the ``"stored"`` copy.
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
    equations: str = "symmetrised"

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
        M = as_csc("M", M)
        H = as_csc("H", H)
        f = as_vector("f", f)
        w = as_vector("w", w)
        mu = as_vector("mu", mu)
        mu_r = as_vector("mu_r", mu_r)

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

        check_finite_sparse("M", M)
        check_finite_sparse("H", H)
        for name, vec in (("f", f), ("w", w), ("mu", mu), ("mu_r", mu_r)):
            check_finite_vector(name, vec)
        for name, vec in (("mu", mu), ("mu_r", mu_r)):
            bad = np.flatnonzero(vec < 0)
            if bad.size:
                raise InvalidProblemError(
                    name, f"is negative ({float(vec[bad[0]])!r}) at contact {bad[0]}"
                          f" ({bad.size} negative in all)",
                    index=int(bad[0]), fix="friction coefficients must be ≥ 0")

        check_positive_diagonal(M)  # before symmetry: a zero diagonal is not an asymmetry
        symmetry = symmetry_report(M)
        if not symmetry.scaled <= max_asymmetry:
            raise asymmetry_error("M", symmetry, max_asymmetry)

        M_sym = symmetrise(M)
        M_sym.sort_indices()
        blocks = block_structure_and_definiteness(M_sym, M)

        if solution is not None:
            solution = _frozen_solution("solution", solution, m, n)
        guesses = tuple(_frozen_solution(f"guesses[{k}]", g, m, n) for k, g in enumerate(guesses))

        problem = cls(
            M=freeze_sparse(M), H=freeze_sparse(H), f=freeze(f), w=freeze(w),
            mu=freeze(mu), mu_r=freeze(mu_r), title=title, description=description,
            math_info=math_info, solution=solution, guesses=guesses,
            storage=dict(storage or {"M": "csc", "H": "csc"}), symmetry=symmetry,
            blocks=blocks, source=source, provenance=dict(provenance or {}),
        )
        object.__setattr__(problem, "M_sym", freeze_sparse(M_sym))
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
        return freeze_sparse(symmetrise(self.M))

    @cached_property
    def matrix_is_symmetric(self) -> bool:
        """True when the stored M (W for a local file) equals its transpose exactly: then the
        symmetrised and the stored equations are the same problem."""
        A = self.local.W if self.local is not None else self.M
        return (abs(A - A.T) > 0).nnz == 0

    @property
    def M_eq(self) -> sp.csc_matrix:
        """The M of the equations this problem poses (see ``equations``): :attr:`M_sym`, or the
        stored M.  Residuals and criteria use it; factorisations use :attr:`M_sym`."""
        return self.M if self.equations == "stored" else self.M_sym

    @property
    def as_stored(self) -> bool:
        """True when the posed equations use the stored, unsymmetric matrix (``equations ==
        "stored"`` and the matrix is not symmetric): a solver must then judge M as stored."""
        return self.equations == "stored" and not self.matrix_is_symmetric

    def stored_equations(self, as_stored: bool = True) -> "Problem":
        """This problem posing its equations with M (W) as stored (``as_stored=True``) or with
        (M + Mᵀ)/2 (``False``); ``self`` when it already does."""
        want = "stored" if as_stored else "symmetrised"
        if self.equations == want:
            return self
        out = dataclasses.replace(self, equations=want)
        object.__setattr__(out, "M_sym", self.M_sym)
        return out

    @property
    def statement(self) -> str:
        """The problem every claim about this object is about, in a few words (DESIGN §1, §6.4):
        always the convex relaxation; for a 3-D file, with μr = 0 and De Saxcé's term dropped
        (so not the Coulomb solution); where the stored matrix is unsymmetric, which matrix the
        equations use; where a local W was shifted to be provable (``--psd-shift``), by how much."""
        X = "W" if self.local is not None else "M"
        text = "the convex relaxation"
        if self.provenance.get("spacedim") == 3:
            text += " of the 3-D problem (μr = 0, De Saxcé's term dropped: not the Coulomb solution)"
        shift = self.provenance.get("psd_shift")
        why = (f" ({PSD_SHIFT_MARK}, ≤ {bound_text(shift['largest_change'])} = {bound_text(shift['relative'], 1)}·‖W‖, added because "
               "W as stored is not positive semidefinite)") if shift else ""
        if not self.matrix_is_symmetric:
            text += (f" with {X}{' + D' if shift else ''} as stored (unsymmetric){why}" if self.equations == "stored"
                     else f" with ({X} + {X}ᵀ)/2{' + D' if shift else ''}{why}")
        elif shift:
            text += f" with W + D{why}"
        return text

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
        out = dataclasses.replace(self, solution=solution)
        object.__setattr__(out, "M_sym", self.M_sym)
        return out

    def __repr__(self) -> str:
        return (f"Problem(title={self.title!r}, m={self.n_dofs}, n={self.n_contacts}, "
                f"nnz(M)={self.M.nnz}, nnz(H)={self.H.nnz})")


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
        vec = as_vector(f"{where}.{name}", arr)
        check_finite_vector(f"{where}.{name}", vec)
        out[name] = freeze(vec)
    return StoredSolution(**out)


def require_problem(obj, argument: str = "problem"):
    """Refuse anything but a :class:`rfverify.Problem` with an :class:`InvalidArgumentError`."""
    if not isinstance(obj, Problem):
        raise InvalidArgumentError(
            argument, f"expected an rfverify.Problem, got {type(obj).__name__}",
            fix="pass the result of rfverify.load(path) or rfverify.Problem.from_arrays(...)")
    if obj.symmetry is None or obj.blocks is None:
        raise InvalidArgumentError(
            argument, "was built by calling rfverify.Problem(...) directly, which does not validate the data "
                      "(shapes, NaN/Inf, μ ≥ 0, M symmetric positive definite)",
            fix="build it with rfverify.Problem.from_arrays(M, H, f, w, mu, mu_r)")
    return obj

