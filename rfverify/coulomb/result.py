"""Results of the physical problem: the double answer (:class:`CoulombSolution`), the
backward-error certificate (:class:`CoulombCertificate`) and the proven path's answer
(:class:`CoulombDigits`), each with the fields every rfverify result has (docs/RESULTS.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..solver.result import ResultAliases, Status
from ..verify.certificate import CertifiedResult, VerdictResult
from .backward import BackwardError

STATEMENT = ("the physical problem (Coulomb friction and rolling resistance with De Saxcé's term "
             "μ‖u_T‖ + μr‖u_R‖ added to u_N)")
NOT_UNIQUE = ("Solutions of the physical problem need not be unique: this is a backward-error certificate "
              "— the exact solution it names solves the physical problem exactly for data that differ from "
              "the file's by δ, not necessarily the file's own (any other) solution")
NOT_UNIQUE_UNCERTIFIED = ("Solutions of the physical problem need not be unique: a certificate of it is a "
                          "backward-error one, about the exact solution for data that differ from the file's by "
                          "δ, not necessarily the file's own (any other) solution")


@dataclass
class CoulombCertificate(VerdictResult):
    """A backward-error certificate of an answer (v, u, r) to the physical problem.

    ``backward`` (:class:`.backward.BackwardError`) bounds δ, per contact, such that the exact
    solution (v*, u*, r*) of the convex problem shifted by ``shift`` solves the physical problem
    exactly for the data w_N + δ; ``quantities`` the proven errors of v, u (the physical
    u = Hᵀv + w), Hr and r against that (v*, u*, r*) (``rfverify.proof.QuantityBound``);
    ``inner`` the :class:`rfverify.Certificate` of the shifted convex problem it rests on.
    ``certified``: every quantity has ``requested`` digits and ``backward.relative`` ≤
    10^-requested.  ``backward_error`` is ``backward.relative`` (the JSON's name)."""

    requested: int
    certified: bool
    verdict: str
    quantities: dict
    backward: BackwardError
    shift: np.ndarray
    inner: object
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)

    @property
    def nit(self) -> int:
        return int(getattr(self.inner, "nit", 0) or 0)

    @property
    def timings(self) -> dict:
        return {"total": self.seconds}

    @property
    def digits(self) -> dict:
        return {k: q.digits for k, q in self.quantities.items() if q.mode != "information"}

    @property
    def backward_error(self) -> float:
        return self.backward.relative

    def __repr__(self) -> str:
        return f"CoulombCertificate(status={self.status}, backward_error={self.backward_error:.1e},\n    {self.headline!r})"

    def as_dict(self) -> dict:
        return {"status": str(self.status), "success": self.success, "message": self.message,
                "problem": "coulomb", "statement": STATEMENT, "requested_digits": self.requested,
                "certified": self.certified, "verdict": self.verdict, "digits": self.digits,
                "backward_error": self.backward_error, "backward": self.backward.as_dict(),
                "quantities": {k: q.as_dict() for k, q in self.quantities.items()},
                "shift_inf": float(np.max(np.abs(self.shift), initial=0.0)),
                "inner_certificate": self.inner.as_dict() if hasattr(self.inner, "as_dict") else None,
                "seconds": self.seconds, **self.extra}


def posed_matrix(problem) -> str:
    """" with (W + Wᵀ)/2" (or M, or "as stored (unsymmetric)") where the file's matrix is
    unsymmetric, naming the equations the answer is proven for; "" where it is symmetric."""
    if problem.matrix_is_symmetric:
        return ""
    X = "W" if problem.local is not None else "M"
    return f" with {X} as stored (unsymmetric)" if problem.equations == "stored" else f" with ({X} + {X}ᵀ)/2"


def coulomb_verdict(requested: int, quantities: dict, backward: BackwardError, inner_valid: bool,
                    inner_failure: str = "", posed: str = "") -> tuple[bool, str]:
    """(certified, verdict): what was proven about the answer, in words; ``posed`` names the
    matrix of the equations where the file's is unsymmetric (:func:`posed_matrix`)."""
    tol = 10.0 ** (-requested)
    if not inner_valid:
        return False, (f"not certified for {STATEMENT}{posed}: the shifted convex problem's proof failed "
                       f"({inner_failure}). {NOT_UNIQUE_UNCERTIFIED}.")
    parts = []
    for q in quantities.values():
        parts.append(q.short())
    bad = [q.name for q in quantities.values() if q.mode != "information" and not q.certified]
    digits_ok = not bad
    be_ok = backward.proven and backward.relative <= tol
    if digits_ok and be_ok and any(q.mode == "absolute" for q in quantities.values()):
        # a quantity proven zero within a bound has no relative digits: not "proven to K digits" (DESIGN §6.3)
        head = f"certified ({requested} digits requested; zero quantities bounded absolutely: {', '.join(parts)})"
    elif digits_ok and be_ok:
        head = f"proven to {requested} digits ({', '.join(parts)})"
    elif digits_ok:
        head = (f"not certified: the digits are proven ({', '.join(parts)}) but the backward error "
                f"{backward.relative:.1e} exceeds 1e-{requested}")
    else:
        head = f"not proven to {requested} digits: {', '.join(bad)} short ({', '.join(parts)})"
    whose = "" if posed else "the file's W and "
    data = (f"for {whose}data q differing from the file's by δ e_N + D r* (D the "
            "diagonal added to W, which as stored is not positive semidefinite)" if backward.psd_part
            else "for data whose w_N differs from the file's by δ")
    certified = digits_ok and be_ok
    text = (f"{head} against the exact solution of {STATEMENT}{posed} {data}, {backward.describe()}. "
            f"{NOT_UNIQUE if certified else NOT_UNIQUE_UNCERTIFIED}.")
    return certified, text


@dataclass
class CoulombSolution(ResultAliases):
    """The double answer to the physical problem (:func:`rfverify.coulomb.solve_coulomb`).

    ``v`` (m,), ``u`` = Hᵀv + w of the file's own data (5n,), ``r`` (5n,); ``shift`` (n,) the
    De Saxcé shift it was solved with; ``outer`` the :class:`.outer.OuterRun`; ``inner`` the
    double :class:`rfverify.SolveResult` of the shifted convex problem; ``residuals`` the
    physical conditions measured (:class:`.model.PhysicalResiduals`).  ``success``: the
    fixed-point residual and the inner criterion are both ≤ ``tol``."""

    v: np.ndarray
    u: np.ndarray
    r: np.ndarray
    shift: np.ndarray
    outer: object
    inner: object
    residuals: object
    tol: float
    timings: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return bool(self.outer.residual <= self.tol and self.inner is not None and self.inner.criterion <= self.tol)

    @property
    def status(self) -> Status:
        if self.success:
            return Status.SOLVED
        if getattr(self.outer, "refused", False):
            return Status.INVALID_INPUT
        if self.inner is None or not math.isfinite(self.outer.residual):
            return Status.NUMERICAL_ERROR
        if self.outer.evaluations >= self.outer.max_evaluations:
            return Status.MAX_ITERATIONS
        return Status.INSUFFICIENT_PROGRESS

    @property
    def message(self) -> str:
        inner = "" if self.inner is None else f"; the last inner solve {self.inner.status}, criterion {self.inner.criterion:.1e}"
        verb = "solved" if self.success else "not solved"
        return (f"{STATEMENT} {verb}: fixed-point residual max|s − Φ(u)| = {self.outer.residual:.1e} of the data "
                f"scale of u after {self.outer.total_evaluations} convex solves ({self.outer.method}); "
                f"{self.outer.message}{inner}")

    @property
    def nit(self) -> int:
        return int(self.outer.total_inner_iterations)

    @property
    def criterion(self) -> float:
        return max(self.outer.residual, self.inner.criterion if self.inner is not None else math.inf)

    def as_dict(self) -> dict:
        return {"status": str(self.status), "success": self.success, "message": self.message, "nit": self.nit,
                "time": self.time, "problem": "coulomb", "statement": STATEMENT, "tol": self.tol,
                "criterion": self.criterion, "fixed_point_residual": self.outer.residual,
                "backward_error": None,  # nothing is proven without --digits: the residual above is measured
                "outer": self.outer.as_dict(),
                "inner_criterion": None if self.inner is None else self.inner.criterion,
                "inner_method": None if self.inner is None else self.inner.method,
                "physical_residuals": self.residuals.as_dict(), "timings": dict(self.timings)}

    def __repr__(self) -> str:  # (the dataclass default printed every array: 200 lines on the Chute)
        return (f"CoulombSolution(status={self.status}, nit={self.nit}, criterion={self.criterion:.1e}, "
                f"time={self.time:.3g} s,\n    {self.message!r})")


@dataclass
class CoulombDigits(CertifiedResult):
    """The proven answer to the physical problem (:func:`rfverify.coulomb.coulomb_to_digits`):
    ``v``, ``u`` (the file's own u = Hᵀv + w), ``r`` float64; ``certificate`` the
    :class:`CoulombCertificate`; ``outer`` the double fixed point; ``inner`` the last
    :class:`rfverify.DigitsSolution` of the shifted convex problem; ``rounds`` one record per
    proven round (the shift updated from each proven answer); ``timings`` seconds (``outer``,
    ``proven``, ``total``)."""

    v: np.ndarray
    u: np.ndarray
    r: np.ndarray
    shift: np.ndarray
    certificate: CoulombCertificate
    outer: object
    inner: object
    rounds: list = field(default_factory=list)
    proven: object = None
    timings: dict = field(default_factory=dict)

    @property
    def digits(self) -> dict:
        return self.certificate.digits

    @property
    def backward_error(self) -> float:
        return self.certificate.backward_error

    @property
    def nit(self) -> int:
        inner = sum(int(r.get("nit", 0)) for r in self.rounds)
        return int(self.outer.total_inner_iterations) + inner

    def as_dict(self) -> dict:
        return {**self.certificate.as_dict(), "status": str(self.status), "success": self.success,
                "nit": self.nit, "time": self.time, "outer": self.outer.as_dict(), "rounds": list(self.rounds),
                "proven_outer": None if self.proven is None else self.proven.as_dict(),
                "timings": dict(self.timings)}

    def __repr__(self) -> str:
        return (f"CoulombDigits(status={self.status}, backward_error={self.backward_error:.1e}, "
                f"time={self.time:.3g} s,\n    {self.certificate.headline!r})")
