"""The product cone of the lifted problem, L3^{n3} × L1^{n1}, as flat vectors.

A flat cone vector (length nz = 3·n3 + n1, L3 cones first) is handed to the row operations
of :mod:`rfverify.jordan` — the code behind the validated public functions, minus their
argument parsing — as one array of cone rows, so each operation is one call whatever the mix
of cones (see :meth:`ProductCone.rows`).  Rows of ordinary magnitude are recognised by one
cheap test of the flat vector and never rescaled, so the hot path is the formulas themselves;
rows of extreme magnitude are rescaled by powers of two exactly as the public functions do.
Row indices are the global cone indices, which domain errors report and
:class:`~rfverify.model.lifting.LiftedProblem` maps to contacts.
"""

from __future__ import annotations

import numpy as np

from .. import jordan
from . import kernels


class ProductCone:
    """Operations on flat vectors of L3^{n3} × L1^{n1} (L3 cones first).

    ``compiled`` (default True): float64 vectors of ordinary magnitude go through the
    compiled kernels of :mod:`rfverify.solver.kernels` (bit for bit the numpy formulas, one
    pass instead of dozens); other dtypes, extreme rows and domain errors take the numpy
    route of :mod:`rfverify.jordan`.  False forces the numpy route (tests compare the two).
    """

    def __init__(self, n3: int, n1: int, compiled: bool = True):
        self.n3 = n3
        self.n1 = n1
        self.compiled = compiled
        self.nz = 3 * n3 + n1
        self.n_cones = n3 + n1
        self._quad_cache = []  # [(array, QuadOperator)], most recent first (quad_operator)
        # Block-diagonal pattern (z index pairs within one cone) in the order of
        # concatenate(Q3.ravel(), Q1.ravel()) for stacks Q3 (n3,3,3), Q1 (n1,1,1).
        c3 = np.arange(n3)
        a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        self.bd_rows = np.concatenate(((3 * c3[:, None, None] + a).ravel(), 3 * n3 + np.arange(n1)))
        self.bd_cols = np.concatenate(((3 * c3[:, None, None] + b).ravel(), 3 * n3 + np.arange(n1)))

    # ------------------------------------------------------------------ layout
    def split(self, x):
        """Views ``(x3 (n3, 3), x1 (n1, 1))`` of a flat cone vector."""
        return x[: 3 * self.n3].reshape(self.n3, 3), x[3 * self.n3:].reshape(self.n1, 1)

    def join(self, x3, x1):
        return np.concatenate((np.asarray(x3).reshape(-1), np.asarray(x1).reshape(-1)))

    def identity(self, dtype=np.float64):
        """e of the product cone: (1, 0, 0) for each L3 cone and 1 for each L1 cone."""
        e = np.zeros(self.nz, dtype=dtype)
        e[0: 3 * self.n3: 3] = 1
        e[3 * self.n3:] = 1
        return e

    def rows(self, x):
        """x as one array of cone rows, row i = cone i: the (n3, 3) view when there are no L1
        cones, the (n1, 1) view when there are no L3 cones, otherwise a copy with each L1 cone
        padded to the L3 row (x, 0, 0).  The jordan formulas on a zero bar are exactly their
        k = 1 forms (λ1 = λ2 = x0, det = x0², Q_x y = x0² y0 …), so a mixed product cone costs
        one call per operation instead of one per family."""
        if not self.n1:
            return x.reshape(self.n3, 3)
        if not self.n3:
            return x.reshape(self.n1, 1)
        r = np.zeros((self.n_cones, 3), dtype=x.dtype)
        r[: self.n3] = x[: 3 * self.n3].reshape(self.n3, 3)
        r[self.n3:, 0] = x[3 * self.n3:]
        return r

    def flat(self, r):
        """The flat vector of a row array from :meth:`rows` (padding dropped)."""
        if not (self.n1 and self.n3):
            return r.reshape(-1)
        return np.concatenate((r[: self.n3].reshape(-1), r[self.n3:, 0]))

    def _compiled(self, *args) -> bool:
        """True when the compiled kernels may take these flat vectors: float64, and no row
        needing the rescaling only the numpy route does (:func:`rfverify.jordan.moderate`)."""
        return (self.compiled and all(isinstance(a, np.ndarray) and a.dtype == np.float64 for a in args)
                and jordan.moderate(*args))

    def _call(self, fn, *args, op: str):
        """``fn(*rows, op=op, scale=...)`` on the flat vectors ``args`` in their common dtype.
        One test of the flat vectors (:func:`rfverify.jordan.moderate`) spares the row
        operation its per-row magnitude test and NaN check for ordinary data."""
        dtype = np.result_type(*args, np.float64)
        args = [np.asarray(a, dtype=dtype) for a in args]
        with np.errstate(all="ignore"):
            return fn(*(self.rows(a) for a in args), op=op, scale=not jordan.moderate(*args))

    # ------------------------------------------------------------------ algebra
    def product(self, x, y):
        if self._compiled(x, y):
            out = np.empty(self.nz)
            kernels.product(self.n3, x, y, out)
            return out
        return self.flat(self._call(jordan.product_rows, x, y, op="jordan_product"))

    def arrow_solve(self, x, y):
        """Solve x ∘ d = y for d (Arw(x)⁻¹ y)."""
        if self._compiled(x, y):
            out = np.empty(self.nz)
            if kernels.arrow_solve(self.n3, x, y, out) < 0:
                return out
        return self.flat(self._call(jordan.arrow_solve_rows, x, y, op="arrow_solve"))

    def quad_apply(self, p, y):
        """Q_p y with p and y checked (see :class:`QuadOperator` for the hot loop)."""
        return self.flat(self._call(lambda a, b, **kw: jordan.quad_apply_rows(jordan.quad_rows(a, **kw), b, **kw),
                                    p, y, op="quad_apply"))

    def quad_operator(self, p) -> "QuadOperator":
        """Q_p as a reusable operator (det p computed once; see :class:`QuadOperator`).  The
        operators of the last few arrays are kept: an iteration asks for Q_p and Q_{p⁻¹} of
        the same arrays in the driver and in the KKT form.  The key is the array object
        itself (held, so its identity cannot be reused), never its contents: an array must
        not be changed in place once an operator was built from it (the solver's never are;
        each iteration's NT point is a fresh array)."""
        for held, op in self._quad_cache:
            if held is p:
                return op
        op = QuadOperator(self, p)
        self._quad_cache = [(p, op)] + self._quad_cache[:3]
        return op

    def inverse(self, x):
        return self.flat(self._call(jordan.inverse_rows, x, op="inverse"))

    def power(self, x, t):
        """x^t cone by cone; t = ±2 in the closed forms x∘x and R x²/det(x)²."""
        return self.flat(self._call(lambda a, **kw: jordan.power_rows(a, t, **kw), x, op=f"power({t})"))

    def _blocks(self, fn, x, op):
        """Diagonal blocks (3×3 per L3 cone, 1 value per L1 cone) as float64, in the order of
        (bd_rows, bd_cols).  A longdouble entry beyond float64's range becomes ±inf, silently:
        the factorisation it is for then fails and says so (a NumericalError naming the form)."""
        with np.errstate(over="ignore"):
            b = np.asarray(self._call(fn, x, op=op), dtype=np.float64)
        if not (self.n1 and self.n3):
            return b.reshape(-1)
        return np.concatenate((b[: self.n3].reshape(-1), b[self.n3:, 0, 0]))

    def quad_blocks(self, p) -> np.ndarray:
        """Values of the block-diagonal Q_p in the order of (bd_rows, bd_cols), float64."""
        if self._compiled(p):
            out = np.empty(9 * self.n3 + self.n1)
            kernels.quad_blocks(self.n3, p, out)
            return out
        return self._blocks(jordan.quad_matrix_rows, p, "quad_matrix")

    def arrow_blocks(self, x) -> np.ndarray:
        """Values of the block-diagonal Arw(x) in the order of (bd_rows, bd_cols), float64."""
        return self._blocks(jordan.arrow_rows, x, "arrow")

    def nt_scaling(self, z, s):
        """NT scaling of the pair, flat: (p, p⁻¹, λ = Q_p z = Q_{p⁻¹} s, cond(Q_p) per cone)."""
        if self._compiled(z, s):
            p, p_inv, lam, cond = np.empty(self.nz), np.empty(self.nz), np.empty(self.nz), np.empty(self.n_cones)
            if kernels.nt_scaling(self.n3, z, s, p, p_inv, lam, cond) < 0:
                return p, p_inv, lam, cond
        r = self._call(jordan.nt_rows, z, s, op="nt_scaling")
        return self.flat(r.p), self.flat(r.p_inv), self.flat(r.lam), np.asarray(r.cond, dtype=np.float64)

    # ------------------------------------------------------------------ step lengths
    def _min_lambda2_along(self, point, dx):
        """(min over cones of λ2(Q_{x^{-1/2}} dx), the first cone that has it) for a point of
        :meth:`_step_point` ((+inf, -1) for no cones)."""
        point, w = point
        if w is not None and self._compiled(dx):
            return kernels.min_ray_lambda2_at(self.n3, w, point.det, dx)
        l2 = self._call(lambda d, **kw: jordan.ray_lambda2_rows(point, d, **kw), dx, op="step_to_boundary")
        if not l2.size:
            return np.inf, -1
        at = int(np.argmin(l2))
        return l2[at], at  # in l2's own precision (longdouble where the run is)

    def max_step(self, x, dx) -> float:
        """Largest α ≥ 0 (possibly ∞) with x + α dx in the cone, for x strictly interior."""
        return self.stepper(x, x)(dx, None)[0]

    def stepper(self, z, s):
        """A function (dz, ds) ↦ (max_step_pair(z, dz, s, ds), limit) for this (z, s), which keeps
        what depends on the point only (x^{-1/2} of each cone) for the next direction; ds = None
        measures dz alone.  ``limit`` = (cone, "z" or "s") is the cone whose boundary sets the
        step (the first cone on ties, the z side on a tie of the two sides), None when the step
        is unbounded."""
        pz = self._step_point(z)
        ps = pz if s is z else self._step_point(s)

        def max_step(dz, ds):
            # α = −1/λ2(y) decreases with −λ2(y): the smallest step belongs to the most negative
            # λ2, so one reduction replaces a division per cone.
            lo, cone = self._min_lambda2_along(pz, dz)
            side = "z"
            if ds is not None:
                lo_s, cone_s = self._min_lambda2_along(ps, ds)
                if lo_s < lo:
                    lo, cone, side = lo_s, cone_s, "s"
            step = float(jordan.step_from_lambda2(np.asarray(lo)))
            return step, (None if step == np.inf else (int(cone), side))

        return max_step

    def _step_point(self, x):
        """(Q_{x^{-1/2}} of an interior x as :func:`rfverify.jordan.step_point_rows` returns
        it, the flat x^{-1/2} for the compiled ray test or None)."""
        if self._compiled(x):
            w, det = np.empty(self.nz), np.empty(self.n_cones)
            if kernels.step_point(self.n3, x, w, det) < 0:
                return jordan.QuadRows(self.rows(w), det, 0), w
        return self._call(jordan.step_point_rows, x, op="step_to_boundary"), None

    def max_step_pair(self, z, dz, s, ds) -> float:
        """min(max_step(z, dz), max_step(s, ds))."""
        return self.stepper(z, s)(dz, ds)[0]

    # ------------------------------------------------------------------ diagnostics
    def min_lambda2(self, x):
        """(smallest λ2 over all cones, its global cone index)."""
        lam = self.lambda2(x)
        k = int(np.argmin(lam))
        return float(lam[k]), k

    def lambda2(self, x) -> np.ndarray:
        if self._compiled(x):
            out = np.empty(self.n_cones)
            kernels.lambda2(self.n3, x, out)
            return out
        return self._call(jordan.spectral_rows, x, op="spectral_values")[1]


class QuadOperator:
    """y ↦ Q_p y = 2(pᵀy)p − det(p) R y for a fixed p, applied many times per iteration.

    The interior-point method applies Q_p and Q_{p⁻¹} a dozen times per iteration (refinement,
    corrector, back-substitution) with the same p, so p is checked and det p (in the
    cancellation-free form of :func:`rfverify.jordan.det`) computed once, and each application
    is a dot product and an axpy per cone, written family by family into the flat result.
    y is trusted: it is the solver's own vector, whose linear solves the interior-point method
    checks for NaN/Inf, and looking at it would cost a fifth of the operation in this hottest
    loop.  For finite y of ordinary size (float64: within 2^±766 when p is ordinary) the
    result is bit for bit :func:`rfverify.jordan.quad_apply`'s; :meth:`ProductCone.quad_apply`
    checks y.
    """

    def __init__(self, cones: ProductCone, p):
        self.cones = cones
        self.p = p
        self._families = None
        self._det = None  # det p per cone, for the compiled kernel (float64 p of ordinary size)
        if cones._compiled(p):
            self._det = np.empty(cones.n_cones)
            kernels.quad_det(cones.n3, p, self._det)
            self._dtype = p.dtype
        else:
            self._prepare()

    def _prepare(self):
        """p as row families for :func:`rfverify.jordan.quad_apply_rows` (numpy route)."""
        cones = self.cones
        prepared = cones._call(jordan.quad_rows, self.p, op="quad_apply")
        self._dtype = prepared.xs.dtype
        self._families = []
        for lo, hi, k, first in ((0, 3 * cones.n3, 3, 0), (3 * cones.n3, cones.nz, 1, cones.n3)):
            if hi > lo:
                rows = slice(first, first + (hi - lo) // k)
                e = prepared.e[rows] if isinstance(prepared.e, np.ndarray) else prepared.e
                fam = jordan.QuadRows(prepared.xs[rows, :k], prepared.det[rows], e)
                self._families.append((fam, lo, hi, k))

    def __call__(self, y):
        y = np.asarray(y)
        if self._det is not None and y.dtype == np.float64:
            out = np.empty(y.shape[0])
            kernels.quad_apply(self.cones.n3, self.p, self._det, y, out)
            return out
        if self._families is None:
            self._prepare()
        out = np.empty(y.shape[0], dtype=np.result_type(y, self._dtype))
        with np.errstate(all="ignore"):
            for fam, lo, hi, k in self._families:
                jordan.quad_apply_rows(fam, y[lo:hi].reshape(-1, k), scale=False,
                                       out=out[lo:hi].reshape(-1, k))
        return out
