"""Linear-system forms of Algorithm 1 (DESIGN §4) behind one interface.

Every form solves the same linearised KKT system for (dv, dr̃, dz)::

    M dv − H̃ᵀ dr̃           = a          (dual residual)
   −H̃ dv          + J dz    = b          (primal residual)
    Q_p dz + Q_{p⁻¹} Jᵀ dr̃  = c          (NT forms;  c = λ \\ ξ in the scaled space)
    Arw(s) dz + Arw(z) Jᵀ dr̃ = c         (noscaling)

but factors a different matrix:

``jqinv``   (14)  [[M, −H̃ᵀ, 0], [−H̃, 0, J Q_{p⁻¹}], [0, Q_{p⁻¹} Jᵀ, I]],  unknowns (dv, dr̃, Q_p dz)
``qp2``     (11)  [[M, −H̃ᵀ, 0], [−H̃, 0, J], [0, Jᵀ, Q_{p²}]],            unknowns (dv, dr̃, dz)
``reduced`` (15)  [[M, −H̃ᵀ], [−H̃, −J Q_{p⁻²} Jᵀ]],                       unknowns (dv, dr̃)
``reduced_factored`` (16)  [[M, −(L⁻¹H̃)ᵀ], [−L⁻¹H̃, −I]], L Lᵀ = J Q_{p⁻²} Jᵀ, unknowns (dv, Lᵀdr̃)
``noscaling`` (6) [[M, −H̃ᵀ, 0], [−H̃, 0, J], [0, Arw(z) Jᵀ, Arw(s)]],      unsymmetric
``schur``   (16) with its identity block eliminated: M + Bᵀ B, B = L⁻¹H̃, SPD, unknowns dv
            (CHOLMOD supernodal Cholesky with the optional extra ``cholmod``, else QDLDL)

The symmetric forms are quasi-definite once a small static regularisation −δI is put on the
dr̃ block (positive blocks M, I or Q_{p²}; negative block dr̃): they are factored by QDLDL
(LDLᵀ without pivoting, AMD ordering, symbolic analysis reused through ``update``).  The
unsymmetric form is factored by SuperLU with partial pivoting, the definite ``schur`` form by
CHOLMOD where it is installed (docs/DECISIONS.md, "Where the factorisation time goes": QDLDL's
entry-by-entry factorisation is the wall from a few thousand contacts on), else by QDLDL.

Iterative refinement runs on the *unreduced, unregularised* three-block system above, with
its residual evaluated by the exact operator (Q applied by Q_x y = 2(xᵀy)x − det(x)Ry, never
formed) in longdouble when asked, and the backward error is judged on one basis for every
form: blockwise over the three block rows, ‖rhs_i − (A x)_i‖∞ / (‖A_i‖∞ ‖x‖∞ + ‖rhs_i‖∞)
with ‖A_i‖∞ the exact row-sum norms of that unreduced operator
(:attr:`KKTSystem.block_norms`), not of the matrix a form factors.

The forms themselves are :mod:`.forms` (``FORMS`` maps method names to them); this module is
what they share.  The interior-point driver sees a form only through three calls (the ``KKTSolver`` protocol):
``update(point) -> bool`` (scale and factor; False when the factorisation fails),
``solve(a, b, c, adapt=...) -> SolveInfo`` and ``set_refinement_dtype(dtype)`` (the driver's
precision schedule).  Static and adaptive regularisation and
iterative refinement are the form's own business.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dataclasses import dataclass
from typing import Protocol

from .cones import ProductCone
from ..engines.factor import QDLDLEngine


@dataclass
class ScalingPoint:
    """What a form needs to build this iteration's matrix: the NT point p and p⁻¹ (symmetric
    forms) or the iterate's cone variables z and s = Jᵀr̃ (noscaling), in the working
    precision."""

    p: object = None
    p_inv: object = None
    z: object = None
    s: object = None


@dataclass
class SolveInfo:
    """A refined solve: the direction, its backward error on the stated basis, the number of
    refinement steps, and whether the adaptive regularisation refactored the matrix."""

    dv: np.ndarray
    dr: np.ndarray
    dz: np.ndarray
    backward_error: float
    steps: int
    refactored: bool = False
    # Ended by the inexact-Newton test (every block residual at most ``forcing`` × its
    # right-hand side) before the backward error reached the refinement target.
    forced: bool = False
    # Ended by that test or at the refinement target (not by the step limit or a stall).
    converged: bool = False
    # ‖residual‖∞ of the returned direction and ‖rhs‖∞, per block row (dual, primal,
    # complementarity).
    block_residuals: tuple = ()
    rhs_norms: tuple = ()


class KKTSolver(Protocol):
    """The calls the interior-point driver makes (see the module docstring)."""

    name: str
    symmetric: bool
    factor_count: int
    unregularised_count: int
    failure: str

    def update(self, point: ScalingPoint) -> bool: ...

    def solve(self, a, b, c, *, adapt: bool = False) -> SolveInfo: ...

    def set_refinement_dtype(self, dtype_ref) -> None: ...


# A predictor solve that needed more refinement steps than this converged at the rate
# δ/(δ + λ_min) of a regularisation in the way (see KKTSystem.solve), even if it ended at the
# inexact-Newton test: the other factorisation is tried, as for a solve that ended far above
# its target.  (On Chute 1368 a float64 predictor took 7 steps and the corrector stalled at
# 10; without δ both took 1–2.)
SLOW_REFINEMENT_STEPS = 3


def abs_max(x) -> float:
    """‖x‖∞, taken on the float64 image of x: a norm needs no more than float64's relative
    precision, and longdouble arithmetic costs five times as much."""
    with np.errstate(over="ignore"):
        return float(np.abs(x.astype(np.float64, copy=False)).max(initial=0.0))


class SparseAssembler:
    """A fixed sparsity pattern assembled from (row, col) contributions, duplicates summed.

    The pattern and the CSC order are computed once; each assembly is one ``bincount``.
    """

    def __init__(self, rows, cols, shape):
        rows = np.asarray(rows, dtype=np.int64)
        cols = np.asarray(cols, dtype=np.int64)
        self.shape = shape
        key = cols * shape[0] + rows
        # np.unique(key, return_inverse=True), with a stable sort: the key is a concatenation
        # of sorted runs (one per block), which timsort merges ten times faster than quicksort.
        order = np.argsort(key, kind="stable")
        sorted_key = key[order]
        first = np.ones(key.size, dtype=bool)
        first[1:] = sorted_key[1:] != sorted_key[:-1]
        uniq = sorted_key[first]
        self.slot = np.empty(key.size, dtype=np.int64)
        self.slot[order] = np.cumsum(first) - 1
        self.indices = (uniq % shape[0]).astype(np.int32)
        col_of = uniq // shape[0]
        self.indptr = np.searchsorted(col_of, np.arange(shape[1] + 1)).astype(np.int32)
        self.nnz = uniq.size

    def matrix(self, values) -> sp.csc_matrix:
        data = np.bincount(self.slot, weights=np.asarray(values, dtype=np.float64), minlength=self.nnz)
        return sp.csc_matrix((data, self.indices, self.indptr), shape=self.shape)


class KKTSystem:
    """Common data and the exact three-block operator used for refinement."""

    symmetric = True
    name = "base"
    # Forms factored through _factor_quasidefinite, with −δ on the dr̃ diagonal that can be
    # dropped (refactor_unregularised); the others need no δ (16) or pivot (6).
    regularisable = False

    def __init__(self, M, H_t, J, cones: ProductCone, *, dtype_ref=np.longdouble, static_reg=1e-12,
                 adaptive_reg=True, refine_max=10, refine_tol=None, forcing=None, M_eq=None):
        self.engine = self._new_engine()  # first: a missing optional engine fails before any work
        self.M = sp.csc_matrix(M)
        self.H_t = sp.csr_matrix(H_t)
        self.J = sp.csr_matrix(J)
        self.cones = cones
        self.m = M.shape[0]
        self.nk = H_t.shape[0]
        self.nz = cones.nz
        self.rho = self.J.tocsc().indices.astype(np.int64)  # J row of each z component
        if np.any(np.diff(self.J.tocsc().indptr) != 1):
            raise ValueError("J must have exactly one entry per column")
        self.static_reg = static_reg
        self.adaptive_reg = adaptive_reg
        self.regularised = False
        self.unregularised_count = 0
        # Set by the driver when the previous iteration needed the factorisation without δ:
        # this one then tries it first instead of paying for the regularised one as well.
        self.prefer_unregularised = False
        self._unregularised_failed = False
        # Exact operator in the refinement precision: one sparse matrix maps (dv, dr̃, dz) to
        # (a, b, Jᵀdr̃) — one matvec per refinement step instead of five — and c is completed
        # with the cone operators, never formed.
        # With ``M_eq`` (an unsymmetric M as stored) the factorisations use the symmetric M and
        # the refinement converges to the direction of the stored system.
        Z = sp.csr_matrix
        self._A = sp.bmat([[self.M if M_eq is None else sp.csc_matrix(M_eq), -self.H_t.T, None],
                           [-self.H_t, None, self.J],
                           [Z((self.nz, self.m)), self.J.T, Z((self.nz, self.nz))]], format="csr")
        self._A_ref = {}
        self._Mcoo = sp.triu(self.M, format="coo")
        self._Hcoo = self.H_t.tocoo()
        self.refine_max = refine_max
        self.forcing = forcing
        self.refine_tol = refine_tol
        self.set_refinement_dtype(dtype_ref)
        self.failure = ""
        # Row sums of |A| of the first two block rows (dual, primal) are fixed; the third
        # (complementarity) block row's change with the point (see _set_point).
        rows = np.asarray(abs(self._A[: self.m + self.nk]).sum(axis=1)).ravel()
        self.block_norms = [float(rows[: self.m].max(initial=0.0)), float(rows[self.m:].max(initial=0.0)), 0.0]
        self._set_form_pattern()

    def set_refinement_dtype(self, dtype_ref):
        """Evaluate refinement residuals in ``dtype_ref`` from now on (the driver's precision
        schedule); the default target is 4·eps of it."""
        self.dtype_ref = np.dtype(dtype_ref)
        if self.dtype_ref not in self._A_ref:
            self._A_ref[self.dtype_ref] = self._A.astype(self.dtype_ref)
        self.A_ref = self._A_ref[self.dtype_ref]
        eps_ref = float(np.finfo(self.dtype_ref).eps)
        self.refine_target = 4 * eps_ref if self.refine_tol is None else self.refine_tol
        # A refined backward error this far above the target means δ is in the way.
        self.reg_fallback_above = max(1e3 * eps_ref, 10 * (self.refine_tol or 0.0))

    def _set_pattern(self, rows, cols, size):
        self.N = size
        self.asm = SparseAssembler(np.concatenate(rows), np.concatenate(cols), (size, size))

    def _set_quasidefinite_pattern(self, rows, cols, size):
        """The pattern in the order :meth:`_factor_quasidefinite` fills it: M and −H̃ᵀ, the
        form's varying blocks (``rows``, ``cols``: lists of index arrays), −δ on the dr̃ diagonal."""
        m, diag = self.m, self.m + np.arange(self.nk)
        Mc, Hc = self._Mcoo, self._Hcoo
        self._set_pattern([Mc.row, Hc.col, *rows, diag], [Mc.col, m + Hc.row, *cols, diag], size)

    def _factor_quasidefinite(self, *varying):
        """Assemble the upper triangle — M and −H̃ᵀ (fixed), this iteration's blocks
        ``varying``, then −δ on the dr̃ diagonal — and factor it with QDLDL, reusing the
        symbolic analysis after the first call."""
        Mdata, Hdata = self._Mcoo.data, -self._Hcoo.data
        self._fixed_vals = np.concatenate((Mdata, Hdata, *varying))
        diag_scale = max(np.abs(Mdata).max(initial=1.0), *(np.abs(v).max(initial=1.0) for v in varying), 1.0)
        self._reg_diag = np.full(self.nk, -self.static_reg * diag_scale)
        self._unregularised_failed = False  # at this matrix (see refactor_unregularised)
        if self.prefer_unregularised and self._try_unregularised():
            return
        self.refactor_regularised()

    def refactor_regularised(self):
        """Factor this iteration's matrix with −δ on the dr̃ diagonal."""
        self._factor_upper(np.concatenate((self._fixed_vals, self._reg_diag)))
        self.regularised = True

    def _try_unregularised(self) -> bool:
        """Factor this iteration's matrix without δ; True if the factorisation is trustworthy:
        no zero pivot (QDLDL refuses one) and the inertia of the true matrix (exactly as many
        negative pivots as dr̃ rows).  On False the caller must factor again."""
        try:
            self._factor_upper(np.concatenate((self._fixed_vals, np.zeros(self.nk))))
            D = self.engine.pivots()
            if np.all(np.isfinite(D)) and np.all(D != 0) and np.count_nonzero(D < 0) == self.nk:
                self.regularised = False
                self.unregularised_count += 1
                return True
        except (RuntimeError, ValueError):  # QDLDL refuses a zero pivot by raising
            pass
        self._unregularised_failed = True
        return False

    def refactor_unregularised(self) -> bool:
        """Factor this iteration's matrix again without δ and keep that factorisation if it is
        trustworthy (see :meth:`_try_unregularised`); otherwise restore the regularised one.
        Returns whether the factorisation without δ was kept (see :meth:`solve` for why).
        If it already failed at this matrix (the iteration tried it first), the regularised
        factorisation in place stays: the same matrix fails the same way."""
        if not self.regularised or self._unregularised_failed:
            return False
        if self._try_unregularised():
            return True
        self.refactor_regularised()
        return False

    def _factor_upper(self, vals):
        """Assemble the upper triangle from ``vals`` (pattern order) and factor it."""
        self.engine.factor(self.asm.matrix(vals))

    def _new_engine(self):
        """The factorisation engine of this form (:mod:`.engines`): QDLDL for the symmetric
        quasi-definite forms; a form with another matrix class overrides this."""
        return QDLDLEngine()

    @property
    def factor_count(self) -> int:
        """Factorisations of this form's matrix that succeeded so far."""
        return self.engine.factorisations

    # ------------------------------------------------------------------ the protocol
    def update(self, point: ScalingPoint) -> bool:
        """Store this iteration's scaling and factor; False (with :attr:`failure` saying why)
        when the factorisation fails — a zero pivot (QDLDL), a singular matrix (SuperLU) or a
        rank-deficient contact block — never for other errors (MemoryError propagates)."""
        self._set_point(point)
        try:
            self.factor()
        except (RuntimeError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            self.failure = f"factorisation of the {self.name} matrix failed ({exc})"
            return False
        self.failure = ""
        return True

    def _set_point(self, point: ScalingPoint):
        """Q_p, Q_{p⁻¹} (or z, s) as operators in the working precision, and ‖A‖∞ for
        this point (see :meth:`operator_norm`)."""
        self.p, self.p_inv, self.z, self.s = point.p, point.p_inv, point.z, point.s
        self._Qp64 = self._Qp_inv64 = None
        if self.symmetric:
            self.Qp = self.cones.quad_operator(self.p)
            self.Qp_inv = self.cones.quad_operator(self.p_inv)
            # Q_{p⁻¹}'s blocks are also the varying block of form (14): kept for factor().
            self.Qp_inv_blocks = self.cones.quad_blocks(self.p_inv)
            blocks = (self.cones.quad_blocks(self.p), self.Qp_inv_blocks)
        else:
            blocks = (self.cones.arrow_blocks(self.s), self.cones.arrow_blocks(self.z))
        rows3 = sum(np.bincount(self.cones.bd_rows, weights=np.abs(b), minlength=self.nz) for b in blocks)
        self.block_norms[2] = float(np.max(rows3, initial=0.0))

    @property
    def operator_norm(self) -> float:
        """‖A‖∞ of the unreduced three-block operator at this point (exact row sums)."""
        return max(self.block_norms)

    # float64 copies for the factorised solves, built on first use (each form needs one; for
    # a float64 point, quad_operator hands back Q_p itself).
    @property
    def Qp64(self):
        if self._Qp64 is None:
            self._Qp64 = self.cones.quad_operator(np.asarray(self.p, dtype=np.float64))
        return self._Qp64

    @property
    def Qp_inv64(self):
        if self._Qp_inv64 is None:
            self._Qp_inv64 = self.cones.quad_operator(np.asarray(self.p_inv, dtype=np.float64))
        return self._Qp_inv64

    def apply(self, x):
        """The three-block operator of the module docstring applied to x = (dv, dr̃, dz),
        flat, in the dtype of x."""
        y = self.A_ref @ x
        mk = self.m + self.nk
        dz, JTdr = x[mk:], y[mk:]
        if self.symmetric:
            y[mk:] = self.Qp(dz) + self.Qp_inv(JTdr)
        else:
            y[mk:] = self.cones.product(self.s, dz) + self.cones.product(self.z, JTdr)
        return y

    # ------------------------------------------------------------------ to be provided
    def _set_form_pattern(self):
        """Once, at construction: the sparsity pattern of the matrix this form factors
        (:meth:`_set_pattern`, or :meth:`_set_quasidefinite_pattern` for a form factored through
        :meth:`_factor_quasidefinite`), in the order :meth:`factor` supplies its values."""
        raise NotImplementedError

    def factor(self):
        raise NotImplementedError

    def solve_once(self, rhs):
        """One solve with the factorisation in float64: flat rhs (a, b, c) → flat (dv, dr̃, dz)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ refinement
    def solve(self, a, b, c, *, adapt: bool = False) -> SolveInfo:
        """Solve with iterative refinement (:meth:`refined`); with ``adapt`` (the predictor
        solve of an iteration) also run the adaptive regularisation: when refinement ends
        far above its target, or needs more than :data:`SLOW_REFINEMENT_STEPS` steps to get
        anywhere, factor the same matrix without δ (or, if this iteration already went without
        δ, with it) and keep whichever solves better.

        Why it is needed: on sticking contacts J Q_{p⁻²} Jᵀ goes to zero, and where H̃ has
        dependent rows (redundant contacts) δ then dominates the dr̃ block in the directions
        H̃ᵀ cannot see, so refinement converges at the rate δ/(δ + λ_min), i.e. not at all.
        δ stays the first choice because it damps the drift of r̃ along null(H̃ᵀ).  After an
        iteration that needed the factorisation without δ, the next tries it first.
        """
        info = self.refined(a, b, c)
        if adapt and self.adaptive_reg and self.regularisable:
            slow = info.steps > SLOW_REFINEMENT_STEPS
            if (info.backward_error > self.reg_fallback_above and not info.forced) or slow:
                if self.regularised:
                    if self.refactor_unregularised():
                        info = self._better_of(info, a, b, c, switch_back=self.refactor_regularised)
                else:
                    self.refactor_regularised()
                    info = self._better_of(info, a, b, c, switch_back=self.refactor_unregularised)
            self.prefer_unregularised = not self.regularised
        return info

    def _better_of(self, info: SolveInfo, a, b, c, switch_back) -> SolveInfo:
        """The solve again with the factorisation just switched to (with or without δ): kept
        if its backward error is smaller than ``info``'s, else ``switch_back()`` restores the
        other factorisation and ``info`` stands."""
        retry = self.refined(a, b, c)
        if retry.backward_error < info.backward_error:
            retry.refactored = True
            return retry
        switch_back()
        return info

    def refined(self, a, b, c) -> SolveInfo:
        """One solve with iterative refinement against the unreduced operator in the
        refinement precision.  The backward error is blockwise: the largest over the three
        block rows i (dual, primal, complementarity) of ‖rhs_i − (A x)_i‖∞ / (‖A_i‖∞ ‖x‖∞ +
        ‖rhs_i‖∞), with ‖A_i‖∞ the exact row-sum norms of :attr:`block_norms` — the same
        basis for every form.  Blockwise, because the complementarity rows carry Q_p and
        Q_{p⁻¹} (norms up to 1/μ): one normwise ratio hides an unresolved primal block behind
        them (on a hyperstatic lattice, refinement then stopped early and pinfeas diverged)."""
        work = self.dtype_ref
        rhs = np.concatenate([np.asarray(t, dtype=work) for t in (a, b, c)])
        x = self.solve_once(rhs).astype(work)
        m, mk = self.m, self.m + self.nk
        cuts = ((0, m), (m, mk), (mk, rhs.size))
        rhs_norms = [abs_max(rhs[i:j]) for i, j in cuts]
        best_rel, best_x, prev = np.inf, x, np.inf
        best_res = ()
        steps = 0
        forced = False
        tiny = np.finfo(float).tiny
        for steps in range(self.refine_max + 1):
            r = rhs - self.apply(x)
            xn = abs_max(x)
            block_res = [abs_max(r[i:j]) for i, j in cuts]
            rel = max(e / max(nrm * xn + rn, tiny) for e, nrm, rn in zip(block_res, self.block_norms, rhs_norms))
            if not np.isfinite(rel):
                best_rel, best_x = float("nan"), x
                break
            # A step that gains less than 20% ends refinement (LAPACK's 0.5 lost the last
            # digits on a hyperstatic lattice; see docs/DECISIONS.md, "Speed").
            if rel < best_rel:
                best_rel, best_x, best_res = rel, x, block_res
            # Inexact Newton: a direction whose every block residual is a small fraction of
            # that block's right-hand side (here the iteration's own residuals) is as good
            # for the iteration as an exact one; relative to the rhs, not to ‖A‖‖x‖, so a
            # large x (dr̃ drifting along null(H̃ᵀ) on redundant contacts) does not hide it.
            forced = (self.forcing is not None and rel == best_rel
                      and all(e <= self.forcing * rn for e, rn in zip(block_res, rhs_norms)))
            if forced or rel <= self.refine_target or steps == self.refine_max or rel > 0.8 * prev:
                break
            prev = rel
            x = x + self.solve_once(r)
        return SolveInfo(best_x[:m], best_x[m:mk], best_x[mk:], float(best_rel), steps, forced=forced,
                         converged=forced or best_rel <= self.refine_target,
                         block_residuals=tuple(best_res), rhs_norms=tuple(rhs_norms))
