"""Certification of a double-precision solution against the mpmath reference (DESIGN §6).

Steps, cheapest first:

(a) residuals of the given (v, u, r) evaluated in high precision (mpmath, ``dps`` digits):
    dynamics, velocity, complementarity and cone membership — no trust in the solver's
    arithmetic.  If they already exceed 10^(−digits), the solution cannot have ``digits``
    correct digits (with a margin of 100 for the data's scale factors); the reference is then
    only run when asked (``always_reference``), to say how many digits it does have.
(b) the reference solution (:func:`reference.solve`, independent mode, ``dps`` digits).
(c) digits = −log10(‖x − x_ref‖∞ / scale) for v, u and Hr, which are unique; for r only
    when it is unique — decided as: H restricted to the columns of the contacts the reference
    finds active (r_N > 0) has full numerical column rank (SVD, σ_min > 1e-10·σ_max) —
    otherwise the distance in r is reported as information only.
    The scale is ‖x_ref‖∞ for v and r.  u = Hᵀv + w and Hr = Mv − f are differences that are
    exactly zero at sticking contacts and at contact-free equilibria, where a relative error
    has no meaning (any double value would have "−∞ digits"); they are measured against the
    terms they are computed from: max(‖u_ref‖, ‖Hᵀv_ref‖, ‖w‖) and max(‖Hr_ref‖, ‖M v_ref‖,
    ‖f‖).  DESIGN §6 writes ‖x_ref‖∞; for these two it is the same whenever x_ref is not
    small compared with its terms.
(d) the verdict: certified to k digits when min(digits of v, u, Hr [, r]) ≥ k.

A claim is only made from the comparison with the reference; residuals alone never certify.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mpmath
import numpy as np

from .errors import InvalidProblemError
from .problem import SPACEDIM, Problem


@dataclass
class Certificate:
    """Result of :func:`certify`.  ``digits`` maps "v", "u", "Hr" (and "r" when unique) to the
    number of correct significant digits (inf when identical); ``certified`` is True when every
    certified quantity has at least ``requested`` digits."""

    requested: int
    certified: bool
    verdict: str
    residuals: dict
    digits: dict = field(default_factory=dict)
    r_unique: bool | None = None
    r_info_digits: float | None = None
    reference: object = None
    reference_ran: bool = False

    def as_dict(self) -> dict:
        return {"requested_digits": self.requested, "certified": self.certified, "verdict": self.verdict,
                "residuals": self.residuals, "digits": self.digits, "r_unique": self.r_unique,
                "r_digits_informational": self.r_info_digits, "reference_ran": self.reference_ran,
                "reference_status": None if self.reference is None else self.reference.status}


def high_precision_residuals(problem: Problem, v, u, r, dps: int = 40) -> dict:
    """Relative residuals of (v, u, r) computed with ``dps``-digit mpmath arithmetic from the
    exact double data (inside ``mpmath.workdps``, so the global precision is restored)."""
    with mpmath.workdps(dps):
        mpf = mpmath.mpf
        V = [mpf(float(x)) for x in v]
        U = [mpf(float(x)) for x in u]
        R = [mpf(float(x)) for x in r]
        M = problem.M_sym.tocoo()
        H = problem.H.tocoo()
        Mv = [mpf(0)] * problem.n_dofs
        for i, j, x in zip(M.row, M.col, M.data):
            Mv[i] += mpf(float(x)) * V[j]
        Hr = [mpf(0)] * problem.n_dofs
        HTv = [mpf(0)] * (SPACEDIM * problem.n_contacts)
        for i, j, x in zip(H.row, H.col, H.data):
            Hr[i] += mpf(float(x)) * R[j]
            HTv[j] += mpf(float(x)) * V[i]
        f = [mpf(float(x)) for x in problem.f]
        w = [mpf(float(x)) for x in problem.w]
        tiny = mpf(10) ** (-300)

        def amax(a):
            return max((abs(x) for x in a), default=mpf(0))

        dyn = amax([a - b - c for a, b, c in zip(Mv, Hr, f)]) / max(amax(Mv), amax(Hr), amax(f), tiny)
        u_scale = max(amax(U), amax(HTv), amax(w), tiny)
        vel = amax([a - b - c for a, b, c in zip(U, HTv, w)]) / u_scale
        r_scale = max(amax(R), tiny)
        comp = abs(mpmath.fsum(a * b for a, b in zip(U, R))) / (r_scale * u_scale * problem.n_contacts)
        prim = dual = mpf(0)
        for i in range(problem.n_contacts):
            m_, mr = mpf(float(problem.mu[i])), mpf(float(problem.mu_r[i]))
            Ri, Ui = R[5 * i:5 * i + 5], U[5 * i:5 * i + 5]
            prim = max(prim, mpmath.hypot(Ri[1], Ri[2]) - m_ * Ri[0], mpmath.hypot(Ri[3], Ri[4]) - mr * Ri[0], -Ri[0])
            dual = max(dual, m_ * mpmath.hypot(Ui[1], Ui[2]) + mr * mpmath.hypot(Ui[3], Ui[4]) - Ui[0], -Ui[0])
        out = {"dynamics": float(dyn), "velocity": float(vel), "complementarity": float(comp),
               "primal_cone": float(prim / r_scale), "dual_cone": float(dual / u_scale)}
    out["max"] = max(out.values())
    return out


def _digits(x: np.ndarray, x_ref: np.ndarray, *terms) -> float:
    scale = max([np.max(np.abs(x_ref), initial=0.0)] + [np.max(np.abs(t), initial=0.0) for t in terms])
    if scale == 0:
        return math.inf if not np.any(x) else 0.0
    err = np.max(np.abs(x - x_ref)) / scale
    return math.inf if err == 0 else float(-math.log10(err))


def r_is_unique(problem: Problem, r_ref: np.ndarray) -> bool:
    """Sufficient test for uniqueness of r: the columns of H of the contacts with r_N > 0
    (active in the reference solution) are linearly independent (σ_min > 1e-10·σ_max)."""
    rc = r_ref.reshape(-1, SPACEDIM)
    active = np.flatnonzero(rc[:, 0] > 1e-14 * max(np.abs(rc[:, 0]).max(), 1e-300))
    if active.size == 0:
        return True
    cols = (SPACEDIM * active[:, None] + np.arange(SPACEDIM)).ravel()
    sub = problem.H[:, cols]
    sub = sub[np.unique(sub.nonzero()[0])].toarray()
    if sub.shape[0] < sub.shape[1]:
        return False
    s = np.linalg.svd(sub, compute_uv=False)
    return bool(s[-1] > 1e-10 * s[0])


def certify(problem: Problem, v, u=None, r=None, *, digits: int = 10, dps: int = 50,
            always_reference: bool = False) -> Certificate:
    """Certify the double-precision solution of ``problem`` to ``digits`` digits.

    The solution is given either as arrays ``v`` (m,), ``u`` (5n,), ``r`` (5n,), or as one
    object with attributes ``v, u, r`` (a :class:`rfverify.solver.SolveResult`, a
    :class:`rfverify.StoredSolution`): ``certify(problem, result, digits=10)``.  A missing u
    is taken as Hᵀv + w.

    Returns a :class:`Certificate`; ``certified`` is True only if the comparison with the
    reference solution shows at least ``digits`` correct digits in v, u, Hr (and r when it is
    unique).  See the module docstring for the steps.
    """
    import reference

    if u is None and r is None and hasattr(v, "v"):
        v, u, r = v.v, getattr(v, "u", None), v.r
    v = np.asarray(v, dtype=np.float64).ravel()
    if u is None and v.size == problem.n_dofs:
        u = problem.H.T @ v + problem.w
    u = v if u is None else u  # wrong-sized v: reported below, before any arithmetic
    v, u, r = (np.asarray(x, dtype=np.float64).ravel() for x in (v, u, r))
    for name, arr, size in (("v", v, problem.n_dofs), ("u", u, SPACEDIM * problem.n_contacts),
                            ("r", r, SPACEDIM * problem.n_contacts)):
        if arr.size != size:
            raise InvalidProblemError(f"solution.{name}", f"has {arr.size} entries, the problem needs {size}",
                                      fix="certify a solution of this problem")
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(u)) and np.all(np.isfinite(r))):
        return Certificate(digits, False, "not certified: the solution contains NaN or Inf", {})
    res = high_precision_residuals(problem, v, u, r, dps=max(30, dps // 2 + 10))
    # A solution right to `digits` digits has residuals of about 10^-digits times the data's
    # scale factors; a margin of 100 keeps this shortcut from refusing a correct solution.
    limit = 10.0 ** (-(digits - 2))
    if res["max"] > limit and not always_reference:
        worst = max((k for k in res if k != "max"), key=res.get)
        return Certificate(digits, False, f"not certified: {worst} residual {res[worst]:.2e} > {limit:.0e}, "
                                          f"too large for a solution with {digits} correct digits "
                                          "(use always_reference / --always-reference for its actual digits)", res)
    ref = reference.solve(problem, dps=dps)
    if not ref.success:
        return Certificate(digits, False, f"not certified: the reference did not converge ({ref.message})",
                           res, reference=ref, reference_ran=True)
    v_ref, u_ref, r_ref = ref.as_float("v"), ref.as_float("u"), ref.as_float("r")
    d = {"v": _digits(v, v_ref),
         "u": _digits(u, u_ref, problem.H.T @ v_ref, problem.w),
         "Hr": _digits(problem.H @ r, problem.H @ r_ref, problem.M_sym @ v_ref, problem.f)}
    unique = r_is_unique(problem, r_ref)
    r_digits = _digits(r, r_ref)
    if unique:
        d["r"] = r_digits
    worst = min(d, key=d.get)
    ok = d[worst] >= digits
    shown = ", ".join(f"{k} {val:.1f}" for k, val in d.items())
    verdict = (f"certified to {digits} digits ({shown})" if ok else
               f"not certified to {digits} digits: {worst} has {d[worst]:.1f} ({shown})")
    return Certificate(digits, ok, verdict, res, d, unique, None if unique else r_digits, ref, True)
