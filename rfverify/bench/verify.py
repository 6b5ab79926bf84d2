"""Independent high-precision recheck of a candidate (v, u, r): the bench counts a run as solved
only on this verdict, never on the solver's word.

The measures are those of :func:`rfverify.check.criterion` (the paper's stopping test in the
original variables) but evaluated in mpmath at ``dps`` digits from the exact double data, by
separate code: no solver arithmetic and no longdouble rounding enters the verdict.

``dinfeas``  ‖M v − f − H r‖₂ / max(‖M v‖₂, ‖f‖₂, ‖H r‖₂)
``velocity`` ‖u − Hᵀ v − w‖₂ / max(‖u‖₂, ‖Hᵀ v‖₂, ‖w‖₂)
``mu``       |uᵀ r| / n                                   (DESIGN §4: absolute, per contact)
``cone``     max(K violation / max(‖r‖∞, ‖Mv‖∞, ‖f‖∞), K* violation / max(‖u‖∞, ‖Hᵀv‖∞, ‖w‖∞))
``max``      the largest of the four — a run meets ``tol`` when ``max ≤ tol``.
"""

from __future__ import annotations

import mpmath
import numpy as np

from ..problem import SPACEDIM, Problem

MEASURES = ("dinfeas", "velocity", "mu", "cone")


class HighPrecisionChecker:
    """Converts a problem's data to mpmath once, then rechecks many candidates (e.g. every
    iterate of a trajectory).  Precision is local (``mpmath.workdps``)."""

    def __init__(self, problem: Problem, dps: int = 30):
        self.problem = problem
        self.dps = dps
        with mpmath.workdps(dps):
            mpf = mpmath.mpf
            M = problem.M_sym.tocoo()
            H = problem.H.tocoo()
            self._M = [(int(i), int(j), mpf(float(x))) for i, j, x in zip(M.row, M.col, M.data)]
            self._H = [(int(i), int(j), mpf(float(x))) for i, j, x in zip(H.row, H.col, H.data)]
            self._f = [mpf(float(x)) for x in problem.f]
            self._w = [mpf(float(x)) for x in problem.w]
            self._mu = [mpf(float(x)) for x in problem.mu]
            self._mu_r = [mpf(float(x)) for x in problem.mu_r]

    def criterion(self, v, u, r) -> dict:
        """The measures of the module docstring for one candidate (float arrays of shapes
        (m,), (5n,), (5n,)); returns floats."""
        p = self.problem
        v, u, r = (np.asarray(x, dtype=np.float64) for x in (v, u, r))
        if v.shape != (p.n_dofs,) or u.shape != (SPACEDIM * p.n_contacts,) or r.shape != u.shape:
            raise ValueError(f"candidate shapes v{v.shape}, u{u.shape}, r{r.shape} do not match the "
                             f"problem (m = {p.n_dofs}, 5n = {SPACEDIM * p.n_contacts})")
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(u)) and np.all(np.isfinite(r))):
            nan = float("nan")
            return {"dinfeas": nan, "velocity": nan, "mu": nan, "cone": nan, "max": float("inf"),
                    "finite": False}
        with mpmath.workdps(self.dps):
            mpf = mpmath.mpf
            V = [mpf(float(x)) for x in v]
            U = [mpf(float(x)) for x in u]
            R = [mpf(float(x)) for x in r]
            zero = mpf(0)
            Mv = [zero] * p.n_dofs
            for i, j, x in self._M:
                Mv[i] += x * V[j]
            Hr = [zero] * p.n_dofs
            HTv = [zero] * len(U)
            for i, j, x in self._H:
                Hr[i] += x * R[j]
                HTv[j] += x * V[i]
            tiny = mpf(10) ** (-300)

            def norm2(a):
                return mpmath.sqrt(mpmath.fsum(x * x for x in a))

            def amax(a):
                return max((abs(x) for x in a), default=zero)

            dinf = norm2([a - b - c for a, b, c in zip(Mv, self._f, Hr)]) / max(
                norm2(Mv), norm2(self._f), norm2(Hr), tiny)
            vel = norm2([a - b - c for a, b, c in zip(U, HTv, self._w)]) / max(
                norm2(U), norm2(HTv), norm2(self._w), tiny)
            gap = abs(mpmath.fsum(a * b for a, b in zip(U, R))) / max(p.n_contacts, 1)
            prim = dual = zero
            for i in range(p.n_contacts):
                Ri, Ui = R[5 * i:5 * i + 5], U[5 * i:5 * i + 5]
                prim = max(prim, mpmath.hypot(Ri[1], Ri[2]) - self._mu[i] * Ri[0],
                           mpmath.hypot(Ri[3], Ri[4]) - self._mu_r[i] * Ri[0], -Ri[0])
                dual = max(dual, self._mu[i] * mpmath.hypot(Ui[1], Ui[2])
                           + self._mu_r[i] * mpmath.hypot(Ui[3], Ui[4]) - Ui[0], -Ui[0])
            # r and M v, f share units (impulse; angular impulse for the rolling parts): when
            # every contact is open, r is rounding noise and its own size is no scale.
            cone = max(prim / max(amax(R), amax(Mv), amax(self._f), tiny),
                       dual / max(amax(U), amax(HTv), amax(self._w), tiny))
            out = {"dinfeas": float(dinf), "velocity": float(vel), "mu": float(gap), "cone": float(cone)}
        out["max"] = max(out[k] for k in MEASURES)
        out["finite"] = True
        return out


def verified_criterion(problem: Problem, v, u, r, dps: int = 30) -> dict:
    """One-off :meth:`HighPrecisionChecker.criterion`."""
    return HighPrecisionChecker(problem, dps).criterion(v, u, r)


def forward_digits(x, x_ref, *scale_terms) -> float:
    """Correct significant digits of ``x`` against ``x_ref``: −log10(‖x − x_ref‖∞ / scale),
    scale = max(‖x_ref‖∞, ‖terms‖∞) (see :mod:`rfverify.certification` for why u and Hr need
    the terms they are computed from).  inf when identical, 0 when no digit is right."""
    x = np.asarray(x, dtype=np.float64)
    x_ref = np.asarray(x_ref, dtype=np.float64)
    if not np.all(np.isfinite(x)):
        return 0.0
    scale = max([np.max(np.abs(x_ref), initial=0.0)] + [np.max(np.abs(t), initial=0.0) for t in scale_terms])
    err = np.max(np.abs(x - x_ref), initial=0.0)
    if err == 0:
        return float("inf")
    if scale == 0:
        return 0.0
    return float(max(0.0, -np.log10(err / scale)))
