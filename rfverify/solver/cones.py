"""The product cone of the lifted problem, L3^{n3} × L1^{n1}, as flat vectors.

A flat cone vector (length nz = 3·n3 + n1, L3 cones first) is viewed as its two families,
(n3, 3) and (n1, 1) arrays without copying, and each operation is the row operation of
:mod:`rfverify.jordan` applied to each family — the code behind the validated public
functions, minus their argument parsing.  Rows of ordinary magnitude are recognised by one
cheap test and never rescaled, so the hot path is the formulas themselves; rows of extreme
magnitude are rescaled by powers of two exactly as the public functions do.  Domain errors
are re-raised with the *global* cone index, which :class:`~rfverify.lifting.LiftedProblem`
maps to a contact.
"""

from __future__ import annotations

import numpy as np

from .. import jordan
from ..errors import ConeDomainError


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

    def _same_dtype(self, *args):
        """Flat vectors in their common working dtype; per-family pairs pass through."""
        dtype = np.result_type(*(a for a in args if not isinstance(a, tuple)), np.float64)
        return [a if isinstance(a, tuple) else np.asarray(a, dtype=dtype) for a in args]

    def _map(self, fn, *args, op: str):
        """``fn(*parts, scale=...)`` on each non-empty family: (result for L3 or None, result
        for L1 or None).

        An argument is a flat vector (split here) or a pair already per family.  One test of
        the flat vectors (:func:`rfverify.jordan.moderate`) spares the row operations their
        per-row magnitude test for ordinary data.  Domain errors are re-raised as ``op`` with
        the global cone index.
        """
        scale = not jordan.moderate(*(a for a in args if not isinstance(a, tuple)))
        fams = [a if isinstance(a, tuple) else self.split(a) for a in args]
        out = [None, None]
        with np.errstate(all="ignore"):
            for fam, size, offset in ((0, self.n3, 0), (1, self.n1, self.n3)):
                if not size:
                    continue
                try:
                    out[fam] = fn(*(f[fam] for f in fams), scale=scale)
                except ConeDomainError as exc:
                    cone = None if exc.cone is None else offset + exc.cone
                    raise ConeDomainError(op, _strip(exc), cone=cone, value=exc.value) from exc
        return tuple(out)

    def _flat(self, fn, *args, op):
        """``fn`` family by family, joined into one flat vector."""
        args = self._same_dtype(*args)
        o3, o1 = self._map(fn, *args, op=op)
        parts = [o.reshape(-1) for o in (o3, o1) if o is not None]
        if len(parts) == 1:
            return parts[0]
        return np.concatenate(parts) if parts else np.empty(0, args[-1].dtype)

    # ------------------------------------------------------------------ algebra
    def product(self, x, y):
        return self._flat(jordan.product_rows, x, y, op="jordan_product")

    def arrow_solve(self, x, y):
        """Solve x ∘ d = y for d (Arw(x)⁻¹ y)."""
        return self._flat(jordan.arrow_solve_rows, x, y, op="arrow_solve")

    def quad_apply(self, p, y):
        return self.quad_operator(p)(y)

    def quad_operator(self, p) -> "QuadOperator":
        """Q_p as a reusable operator (det p computed once; see :class:`QuadOperator`)."""
        return QuadOperator(self, p)

    def inverse(self, x):
        return self._flat(jordan.inverse_rows, x, op="inverse")

    def power(self, x, t):
        """x^t cone by cone; t = ±2 in the closed forms x∘x and x⁻¹∘x⁻¹."""
        return self._flat(lambda a, scale: jordan.power_rows(a, t, scale=scale), x, op=f"power({t})")

    def _blocks(self, fn, x, op):
        b3, b1 = self._map(fn, *self._same_dtype(x), op=op)
        parts = [np.asarray(b, dtype=np.float64).ravel() for b in (b3, b1) if b is not None]
        return np.concatenate(parts) if parts else np.empty(0)

    def quad_blocks(self, p) -> np.ndarray:
        """Values of the block-diagonal Q_p in the order of (bd_rows, bd_cols), float64."""
        return self._blocks(jordan.quad_matrix_rows, p, "quad_matrix")

    def arrow_blocks(self, x) -> np.ndarray:
        """Values of the block-diagonal Arw(x) in the order of (bd_rows, bd_cols), float64."""
        return self._blocks(jordan.arrow_rows, x, "arrow")

    def nt_scaling(self, z, s):
        """NT scaling of the pair, flat: (p, p⁻¹, λ = Q_p z = Q_{p⁻¹} s, cond(Q_p) per cone)."""
        z, s = self._same_dtype(z, s)
        fams = [r for r in self._map(jordan.nt_rows, z, s, op="nt_scaling") if r is not None]
        if not fams:
            return z.copy(), z.copy(), z.copy(), np.empty(0)
        p, p_inv, lam = (np.concatenate([np.ravel(getattr(r, f)) for r in fams]) for f in ("p", "p_inv", "lam"))
        cond = np.concatenate([np.asarray(r.cond, dtype=np.float64) for r in fams])
        return p, p_inv, lam, cond

    # ------------------------------------------------------------------ step lengths
    def _step_points(self, x):
        return self._map(jordan.step_point_rows, x, op="step_to_boundary")

    def _min_lambda2_along(self, points, dx):
        """min over cones of λ2(Q_{x^{-1/2}} dx) (+inf for no cones)."""
        l3, l1 = self._map(jordan.ray_lambda2_rows, points, dx, op="step_to_boundary")
        return min((np.min(l) for l in (l3, l1) if l is not None and l.size), default=np.inf)

    def max_step(self, x, dx) -> float:
        """Largest α ≥ 0 (possibly ∞) with x + α dx in the cone, for x strictly interior."""
        x, dx = self._same_dtype(x, dx)
        return float(jordan.step_from_lambda2(np.asarray(self._min_lambda2_along(self._step_points(x), dx))))

    def stepper(self, z, s):
        """A function (dz, ds) ↦ max_step_pair(z, dz, s, ds) for this (z, s), which keeps what
        depends on the point only (x^{-1/2} of each cone) for the next direction."""
        z, s = self._same_dtype(z, s)
        pz, ps = self._step_points(z), self._step_points(s)

        def max_step(dz, ds):
            dz, ds = (np.asarray(d, dtype=z.dtype) for d in (dz, ds))
            # α = −1/λ2(y) decreases with −λ2(y): the smallest step belongs to the most negative
            # λ2, so one reduction replaces a division per cone.
            lo = min(self._min_lambda2_along(pz, dz), self._min_lambda2_along(ps, ds))
            return float(jordan.step_from_lambda2(np.asarray(lo)))

        return max_step

    def max_step_pair(self, z, dz, s, ds) -> float:
        """min(max_step(z, dz), max_step(s, ds))."""
        return self.stepper(z, s)(dz, ds)

    # ------------------------------------------------------------------ diagnostics
    def min_lambda2(self, x):
        """(smallest λ2 over all cones, its global cone index)."""
        lam = self.lambda2(x)
        k = int(np.argmin(lam))
        return float(lam[k]), k

    def lambda2(self, x) -> np.ndarray:
        return self._flat(lambda a, scale: jordan.spectral_rows(a, scale=scale)[1], x, op="spectral_values")


class QuadOperator:
    """y ↦ Q_p y = 2(pᵀy)p − det(p) R y for a fixed p, applied many times per iteration.

    The interior-point method applies Q_p and Q_{p⁻¹} a dozen times per iteration (refinement,
    corrector, back-substitution) with the same p, so det p (in the cancellation-free form of
    :func:`rfverify.jordan.det`) is computed once and each application is a dot product and
    an axpy per cone.
    """

    def __init__(self, cones: ProductCone, p):
        self.cones = cones
        self.p = p
        self._prepared = cones._map(jordan.quad_rows, *cones._same_dtype(p), op="quad_apply")

    def __call__(self, y):
        return self.cones._flat(jordan.quad_apply_rows, self._prepared, y, op="quad_apply")


def _strip(exc: ConeDomainError) -> str:
    text = str(exc)
    head = f"{exc.operation} (cone {exc.cone}): " if exc.cone is not None else f"{exc.operation}: "
    return text[len(head):] if text.startswith(head) else text
