"""The product cone of the lifted problem, L3^{n3} × L1^{n1}, as flat vectors.

A thin layer over :mod:`rfverify.jordan`: each operation splits a flat cone vector (length
nz = 3·n3 + n1) into its two families and makes one vectorised Jordan call per family, so
nothing loops over contacts.  Domain errors are re-raised with the *global* cone index, which
:class:`~rfverify.lifting.LiftedProblem` maps to a contact.

The operations the interior-point method calls every iteration first try the column-wise
kernels of :mod:`rfverify.solver.columns` (same formulas, no per-call validation or
rescaling) and fall back to :mod:`rfverify.jordan` whenever a kernel declines — extreme
magnitudes, a point not interior, a non-finite result — so errors are still reported by
the validated implementation, with the cone that caused them.
"""

from __future__ import annotations

import numpy as np

from .. import jordan
from ..errors import ConeDomainError
from . import columns


class ProductCone:
    """Operations on flat vectors of L3^{n3} × L1^{n1} (L3 cones first)."""

    def __init__(self, n3: int, n1: int):
        self.n3 = n3
        self.n1 = n1
        self.nz = 3 * n3 + n1
        self.n_cones = n3 + n1
        # Block-diagonal pattern (z index pairs within one cone) in the order of
        # concatenate(Q3.ravel(), Q1.ravel()) for stacks Q3 (n3,3,3), Q1 (n1,1,1).
        c3 = np.arange(n3)
        a, b = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        self.bd_rows = np.concatenate(((3 * c3[:, None, None] + a).ravel(), 3 * n3 + np.arange(n1)))
        self.bd_cols = np.concatenate(((3 * c3[:, None, None] + b).ravel(), 3 * n3 + np.arange(n1)))

    # ------------------------------------------------------------------ layout
    def split(self, x):
        return x[: 3 * self.n3].reshape(self.n3, 3), x[3 * self.n3:].reshape(self.n1, 1)

    def join(self, x3, x1):
        return np.concatenate((np.asarray(x3).reshape(-1), np.asarray(x1).reshape(-1)))

    def identity(self, dtype=np.float64):
        e = np.zeros(self.nz, dtype=dtype)
        e[0: 3 * self.n3: 3] = 1
        e[3 * self.n3:] = 1
        return e

    def _same_dtype(self, *args):
        dtype = np.result_type(*args, np.float64)
        return [np.asarray(a, dtype=dtype) for a in args]

    def _map(self, fn, *args, op: str):
        """Apply ``fn`` family by family; re-raise domain errors with the global cone index."""
        out3 = out1 = None
        parts = [self.split(a) for a in args]
        if self.n3:
            try:
                out3 = fn(*(p[0] for p in parts))
            except ConeDomainError as exc:
                raise ConeDomainError(op, _strip(exc), cone=exc.cone, value=exc.value) from exc
        if self.n1:
            try:
                out1 = fn(*(p[1] for p in parts))
            except ConeDomainError as exc:
                cone = None if exc.cone is None else self.n3 + exc.cone
                raise ConeDomainError(op, _strip(exc), cone=cone, value=exc.value) from exc
        return out3, out1

    def _flat(self, fn, *args, op):
        o3, o1 = self._map(fn, *args, op=op)
        dtype = np.result_type(*args)
        return self.join(o3 if o3 is not None else np.empty((0, 3), dtype),
                         o1 if o1 is not None else np.empty((0, 1), dtype))

    # ------------------------------------------------------------------ algebra
    def product(self, x, y):
        fast = columns.product(*self._same_dtype(x, y), self.n3)
        return fast if fast is not None else self._flat(jordan.jordan_product, x, y, op="jordan_product")

    def arrow_solve(self, x, y):
        """Solve x ∘ d = y for d (Arw(x)⁻¹ y)."""
        fast = columns.arrow_solve(*self._same_dtype(x, y), self.n3)
        return fast if fast is not None else self._flat(jordan.arrow_solve, x, y, op="arrow_solve")

    def quad_apply(self, p, y):
        return self._flat(jordan.quad_apply, p, y, op="quad_apply")

    def quad_operator(self, p) -> "QuadOperator":
        """Q_p as a reusable operator (det p computed once; see :class:`QuadOperator`)."""
        return QuadOperator(self, p)

    def inverse(self, x):
        return self._flat(jordan.inverse, x, op="inverse")

    def power(self, x, t):
        return self._flat(lambda a: jordan.power(a, t), x, op=f"power({t})")

    def quad_blocks(self, p) -> np.ndarray:
        """Values of the block-diagonal Q_p in the order of (bd_rows, bd_cols), float64."""
        fast = columns.quad_blocks(*self._same_dtype(p), self.n3)
        if fast is not None:
            return fast
        q3, q1 = self._map(jordan.quad_matrix, p, op="quad_matrix")
        parts = [np.asarray(q, dtype=np.float64).ravel() for q in (q3, q1) if q is not None]
        return np.concatenate(parts) if parts else np.empty(0)

    def arrow_blocks(self, x) -> np.ndarray:
        """Values of the block-diagonal Arw(x) in the order of (bd_rows, bd_cols), float64."""
        a3, a1 = self._map(jordan.arrow, x, op="arrow")
        parts = [np.asarray(a, dtype=np.float64).ravel() for a in (a3, a1) if a is not None]
        return np.concatenate(parts) if parts else np.empty(0)

    def nt_scaling(self, z, s):
        """NT scaling of the pair, flat: (p, p⁻¹, λ = Q_p z = Q_{p⁻¹} s, cond(Q_p) per cone)."""
        fast = columns.nt_scaling(*self._same_dtype(z, s), self.n3)
        if fast is not None:
            return fast.p, fast.p_inv, fast.lam, fast.cond
        r3, r1 = self._map(jordan.nt_scaling, z, s, op="nt_scaling")
        dtype = np.result_type(z, s)
        empty3, empty1 = np.empty((0, 3), dtype), np.empty((0, 1), dtype)
        p = self.join(r3.p if r3 is not None else empty3, r1.p if r1 is not None else empty1)
        p_inv = self.join(r3.p_inv if r3 is not None else empty3, r1.p_inv if r1 is not None else empty1)
        lam = self.join(r3.lam if r3 is not None else empty3, r1.lam if r1 is not None else empty1)
        cond = np.concatenate((np.asarray(r3.cond if r3 is not None else np.empty(0), dtype=np.float64).ravel(),
                               np.asarray(r1.cond if r1 is not None else np.empty(0), dtype=np.float64).ravel()))
        return p, p_inv, lam, cond

    def max_step(self, x, dx) -> float:
        """Largest α ≥ 0 (possibly ∞) with x + α dx in the cone, for x strictly interior."""
        a3, a1 = self._map(lambda a, b: jordan.step_to_boundary(a, b), x, dx, op="step_to_boundary")
        vals = [np.min(a) for a in (a3, a1) if a is not None and np.size(a)]
        return float(min(vals)) if vals else float("inf")

    def stepper(self, z, s):
        """A function (dz, ds) ↦ max_step_pair(z, dz, s, ds) for this (z, s), which keeps what
        depends on the point only (x^{-1/2} of each cone) for the next direction."""
        z_, s_ = self._same_dtype(z, s)
        pz = columns.step_point(z_, self.n3)
        ps = columns.step_point(s_, self.n3) if pz is not None else None

        def max_step(dz, ds):
            if ps is not None:
                dz_, ds_ = (np.asarray(d, dtype=z_.dtype) for d in (dz, ds))
                az = pz.min_step(dz_)
                a_s = ps.min_step(ds_) if az is not None else None
                if a_s is not None:
                    return min(az, a_s)
            return self._max_step_pair_checked(z, dz, s, ds)

        return max_step

    def max_step_pair(self, z, dz, s, ds) -> float:
        """min(max_step(z, dz), max_step(s, ds)) in one vectorised call per family."""
        return self.stepper(z, s)(dz, ds)

    def _max_step_pair_checked(self, z, dz, s, ds) -> float:
        """max_step_pair by :mod:`rfverify.jordan` (rescaling, precise errors)."""
        z3, z1 = self.split(z)
        s3, s1 = self.split(s)
        d3, d1 = self.split(dz)
        e3, e1 = self.split(ds)
        vals = []
        for x, dx, off in ((np.concatenate((z3, s3)), np.concatenate((d3, e3)), 0),
                           (np.concatenate((z1, s1)), np.concatenate((d1, e1)), self.n3)):
            if x.shape[0] == 0:
                continue
            try:
                vals.append(np.min(jordan.step_to_boundary(x, dx)))
            except ConeDomainError as exc:
                n_fam = x.shape[0] // 2
                cone = None if exc.cone is None else off + exc.cone % n_fam
                raise ConeDomainError("step_to_boundary", _strip(exc), cone=cone, value=exc.value) from exc
        return float(min(vals)) if vals else float("inf")

    def min_lambda2(self, x):
        """(smallest λ2 over all cones, its global cone index)."""
        lam = self.lambda2(x)
        k = int(np.argmin(lam))
        return float(lam[k]), k

    def lambda2(self, x) -> np.ndarray:
        fast = columns.lambda2(*self._same_dtype(x), self.n3)
        if fast is not None:
            return fast
        x3, x1 = self.split(x)
        parts = []
        if self.n3:
            parts.append(jordan.spectral_values(x3)[1])
        if self.n1:
            parts.append(x1[:, 0])
        return np.concatenate(parts)



class QuadOperator:
    """y ↦ Q_p y = 2(pᵀy)p − det(p) R y for a fixed p, applied many times per iteration.

    The interior-point method applies Q_p and Q_{p⁻¹} a dozen times per iteration (refinement,
    corrector, back-substitution) with the same p, so det p (in the cancellation-free form of
    :func:`rfverify.jordan.det`) is computed once and each application is a dot product and
    an axpy per cone.  The power-of-two rescaling of :func:`rfverify.jordan.quad_apply` is
    only needed for points of extreme magnitude; for those (never met in practice, where
    |p| ~ μ^{±1/2}) the operator defers to it.
    """

    def __init__(self, cones: ProductCone, p):
        self.cones = cones
        self.p = p
        p3, p1 = cones.split(p)
        self._direct = columns.moderate(np.asarray(p))
        if self._direct:
            self._det3 = columns.det3(p, cones.n3)
            self._sq1 = p1[:, 0] * p1[:, 0]

    def __call__(self, y):
        if not self._direct:
            return self.cones.quad_apply(self.p, y)
        return columns.quad_apply(self.p, self._det3, self._sq1, y, self.cones.n3)


def _strip(exc: ConeDomainError) -> str:
    text = str(exc)
    head = f"{exc.operation} (cone {exc.cone}): " if exc.cone is not None else f"{exc.operation}: "
    return text[len(head):] if text.startswith(head) else text

