"""The physical problem's entry points: solve it (double), solve it with a proven backward
error (the k-digit path on the shifted convex problem), and certify a given answer.

:func:`rfverify.solve`, :func:`rfverify.solve_to_digits` and :func:`rfverify.certify` call these
with ``problem="coulomb"`` (``rfverify/__init__.py``); the CLI with ``--problem coulomb``.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..errors import InvalidArgumentError
from ..model.problem import Problem
from ..proof import ProofContext, validate_digits
from ..proof.quantity import DATA_SCALE_NAMES, DATA_SCALE_NAMES_LOCAL
from ..proof.dyadic import Dyadic
from .backward import backward_bound, physical_quantities
from .model import PROBLEMS, offsets, phi, physical_of_inner, physical_residuals, physical_velocity, shifted_problem
from .outer import OUTER_TOL, find_shift, fixed_point
from .result import CoulombCertificate, CoulombDigits, CoulombSolution, coulomb_verdict, posed_matrix

PROVEN_ROUNDS = 12
"""Proven rounds at most: the outer iteration continued with proven answers (the double ones
are accurate to the double solves' forward error only: on the chute |Φ(û_double) − Φ(û)| is
1.8e-9 where the double fixed-point residual is 4e-14), until the backward error is below
10^-digits."""
PROVEN_STALL = 4
"""Proven rounds without a 10% gain on the best backward error before the rounds stop.  A
generated 101-contact MassRatio needs 9 rounds (1.9e-8, 1.1e-9, 9.5e-10, 1.1e-9, 8.8e-10, 2.5e-10,
…, 4.4e-11) — Anderson's secant model needs a few rounds where Φ grows faster than s — and
with 2 it stopped at the fifth (8.8e-10, not certified)."""


def check_problem_kind(kind) -> str:
    """``kind`` if it names a problem (:data:`.model.PROBLEMS`), else an InvalidArgumentError."""
    if kind not in PROBLEMS:
        raise InvalidArgumentError("problem", f"{kind!r} is not one of {', '.join(PROBLEMS)}",
                                   fix="pass problem='relaxation' (default) or problem='coulomb'")
    return kind


def _inner_tol(tol: float) -> float:
    """Each inner solve's tolerance: two decades below ``tol`` (the fixed point inherits the
    inner answers' accuracy), but not below what double precision reaches."""
    return max(tol * 1e-2, 1e-13)


def _deadline(time_limit):
    if time_limit is not None and not (isinstance(time_limit, (int, float)) and time_limit > 0):
        raise InvalidArgumentError("time_limit", f"must be a number of seconds > 0, got {time_limit!r}",
                                   fix="pass e.g. time_limit=60, or None for no limit")
    return None if time_limit is None else time.perf_counter() + time_limit


def solve_coulomb(problem: Problem, method: str = "auto", tol: float = 1e-10, max_iter: int = 100, *,
                  outer: str = "anderson", outer_tol: float | None = None, outer_max_iter: int = 100,
                  as_stored: bool | None = None, progress=None, time_limit: float | None = None,
                  start=None, continuation: bool = True, **options) -> CoulombSolution:
    """Solve the physical problem (De Saxcé's term kept) in double: the outer iteration on the
    shift (:func:`.outer.fixed_point`, ``outer`` "anderson" or "picard") over double solves of
    the shifted convex problem (``method``, ``max_iter``, ``options``: :func:`rfverify.solve`'s,
    each to ``max(tol·1e-2, 1e-13)``).  Solved when the fixed-point residual max|s − Φ(u)|
    relative to the data scale of u and the last inner criterion are both ≤ ``tol``;
    ``outer_tol`` (default ``tol``/10) stops the outer loop.  ``u`` is the file's own Hᵀv + w.
    ``start``: the shift (n,) the outer iteration starts from (:func:`start_shift`; default 0, the
    relaxation's answer) — e.g. that of another solver's answer, where the iteration from 0 stalls
    in a basin with no fixed point (docs/DECISIONS.md, "The physical problem").
    ``continuation``: where the iteration stops above a residual of 1e-8, follow the solution from the
    frictionless problem with μ and μr scaled up to theirs (:func:`.outer.find_shift`; default on)."""
    from ..solver import posed

    t0 = time.perf_counter()
    deadline = _deadline(time_limit)
    problem = posed(problem, as_stored, method)
    run = find_shift(problem, method=method, max_iter=max_iter, outer=outer,
                     outer_tol=tol / 10 if outer_tol is None else outer_tol, outer_max_iter=outer_max_iter,
                     inner_tol=_inner_tol(tol), progress=progress, deadline=deadline,
                     start=start_shift(problem, start), continuation=continuation, **options)
    inner = run.inner
    if inner is None:
        n5 = 5 * problem.n_contacts
        v, u, r = np.full(problem.n_dofs, np.nan), np.full(n5, np.nan), np.full(n5, np.nan)
    else:
        v, r = inner.v, inner.r
        u = physical_velocity(problem, v, r)
    res = physical_residuals(problem, u, r, run.shift, run.scale)
    return CoulombSolution(v=v, u=u, r=r, shift=run.shift, outer=run, inner=inner, residuals=res, tol=tol,
                           timings={"outer": run.seconds, "total": time.perf_counter() - t0})


def _scales(problem: Problem) -> tuple[dict, str]:
    """The problem's proven data scales (DESIGN §6.3) and the name of u's."""
    names = DATA_SCALE_NAMES_LOCAL if problem.local is not None else DATA_SCALE_NAMES
    return ProofContext(problem).scales, names["u"]


def coulomb_certificate(problem: Problem, shifted: Problem, inner_cert, v, u_inner, r, digits: int,
                        scales: tuple, relative: bool = False, u_phys=None, extra=None) -> CoulombCertificate:
    """The :class:`CoulombCertificate` of (v, u_phys, r) from ``inner_cert``, the certificate of
    (v, u_inner, r) for ``shifted`` (the problem with w_N + ŝ)."""
    t0 = time.perf_counter()
    scale_dict, scale_name = scales
    u_phys = physical_velocity(problem, v, r) if u_phys is None else np.asarray(u_phys, dtype=np.float64)
    proof = inner_cert.proof
    valid = proof is not None and proof.valid
    e_u = proof.quantities["u"].abs_bound if valid else math.inf
    be = backward_bound(problem, shifted, u_inner, e_u, scale_dict["u"], scale_name,
                        **_psd_terms(problem, proof if valid else None, r))
    if valid:
        quantities = physical_quantities(problem, shifted, proof, u_phys, u_inner, scale_dict, digits, relative)
    else:
        quantities = {}
    failure = "" if valid else (proof.failure if proof is not None else inner_cert.verdict)
    certified, verdict = coulomb_verdict(digits, quantities, be, valid, failure, posed_matrix(problem))
    s = np.asarray((Dyadic.from_float(offsets(shifted)) - Dyadic.from_float(offsets(problem))).nearest()[0::5])
    extra = dict(extra or {})
    if getattr(inner_cert, "extra", {}).get("time_limit") is not None and not certified:
        extra["time_limit"] = inner_cert.extra["time_limit"]
    return CoulombCertificate(digits, certified, verdict, quantities, be, s, inner_cert,
                              seconds=time.perf_counter() - t0, extra=extra)


def coulomb_to_digits(problem: Problem, digits: int = 10, method: str = "auto", tol: float = 1e-10,
                      max_iter: int = 100, *, outer: str = "anderson", outer_tol: float = OUTER_TOL,
                      outer_max_iter: int = 100, proven_rounds: int = PROVEN_ROUNDS, relative: bool = False,
                      as_stored: bool | None = None, progress=None, time_limit: float | None = None,
                      start=None, continuation: bool = True, **options) -> CoulombDigits:
    """Solve the physical problem with a proven backward error (issue 51): the double fixed
    point on the shift (:func:`solve_coulomb`'s, to ``outer_tol``), then the proven k-digit path
    (:func:`rfverify.solve_to_digits`, ``digits``) on the convex problem with w_N + ŝ, and the
    bound on δ (:mod:`.backward`).  Where that bound is above 10^-digits of the data scale of u,
    ŝ ← Φ(û) of the proven answer and the path runs again (``proven_rounds`` in all).  Certified
    when v, u, Hr (and r where unique) have ``digits`` proven digits against the exact solution
    of the physical problem with data w_N + δ and the relative bound on δ is ≤ 10^-digits.
    ``start`` and ``continuation``: as :func:`solve_coulomb`'s."""
    from ..verify.digits import solve_to_digits
    from ..solver import posed

    t0 = time.perf_counter()
    digits = validate_digits(digits)
    deadline = _deadline(time_limit)
    problem = posed(problem, as_stored, method)
    say = progress or (lambda msg: None)
    run = find_shift(problem, method=method, max_iter=max_iter, outer=outer, outer_tol=outer_tol,
                     outer_max_iter=outer_max_iter, inner_tol=_inner_tol(tol), progress=progress,
                     deadline=deadline, start=start_shift(problem, start), continuation=continuation, **options)
    say(f"fixed point ({run.method}): residual {run.residual:.1e} after {run.total_evaluations} convex solves; "
        f"{run.message}")
    t_outer = time.perf_counter() - t0
    scales = _scales(problem)
    rounds, certs = [], []

    def evaluate(shifted):  # one proven round: the k-digit path on the shifted problem, and δ bounded
        left = None if deadline is None else max(deadline - time.perf_counter(), 1e-3)
        sol = solve_to_digits(shifted, digits, method, tol, max_iter, relative=relative, progress=progress,
                              time_limit=left, _named_limit=time_limit, **options)
        u_phys = physical_of_inner(problem, shifted, sol.u)
        cert = coulomb_certificate(problem, shifted, sol.certificate, sol.v, sol.u, sol.r, digits, scales, relative,
                                   u_phys=u_phys, extra={"proven_round": len(rounds)})
        rounds.append({"round": len(rounds), "nit": sol.nit, "inner_status": str(sol.status),
                       "backward_error": cert.backward_error, "fixed_point_part": cert.backward.fixed_point_part,
                       "certified": cert.certified, "seconds": sol.time})
        certs.append((cert, sol, u_phys))
        say(f"proven round {len(rounds) - 1}: {cert.backward.describe()}; inner {sol.status}")
        return sol, sol.u

    def done(sol):
        cert = certs[-1][0]
        return cert.certified or not cert.backward.proven or sol.timed_out or sol.interrupted

    proven = fixed_point(problem, outer=outer, outer_tol=0.0, outer_max_iter=max(1, proven_rounds), start=run.shift,
                         deadline=deadline, evaluate=evaluate, done=done, label="proven round", stall=PROVEN_STALL)
    cert, sol, u = certs[0]
    for c, s_, u_ in certs[1:]:
        if _better(c, cert):
            cert, sol, u = c, s_, u_
    return CoulombDigits(v=sol.v, u=u, r=sol.r, shift=cert.shift, certificate=cert, outer=run, inner=sol,
                         rounds=rounds, proven=proven,
                         timings={"outer": t_outer, "proven": time.perf_counter() - t0 - t_outer,
                                  "total": time.perf_counter() - t0})


def _psd_terms(problem: Problem, proof, r) -> dict:
    """``diag_shift`` and ``r_upper`` of :func:`.backward.backward_bound` where the local W was
    shifted (``--psd-shift``): max_k D_kk and ‖r*_i‖∞ ≤ ‖r̂_i‖∞ + the proof's bound on r (inf
    where the proof bounds no r)."""
    shift = problem.provenance.get("psd_shift")
    if not shift:
        return {}
    q_r = None if proof is None else proof.quantities.get("r")
    e_r = q_r.abs_bound if q_r is not None else math.inf  # an "information" r may still be bounded
    if not math.isfinite(e_r):  # (nan too: no bound)
        return {"diag_shift": float(shift["largest_change"]), "r_upper": None}
    R = np.abs(np.asarray(r, dtype=np.float64)).reshape(-1, 5).max(axis=1)
    return {"diag_shift": float(shift["largest_change"]), "r_upper": np.nextafter(R + e_r, math.inf)}


def _better(a: CoulombCertificate, b: CoulombCertificate) -> bool:
    """True when certificate ``a`` says more than ``b``: certified first, then the smaller
    backward error."""
    if a.certified != b.certified:
        return a.certified
    return a.backward_error < b.backward_error


def certify_coulomb(problem: Problem, v, u=None, r=None, *, digits: int = 10, relative: bool = False,
                    as_stored: bool | None = None, progress=None, time_limit: float | None = None,
                    polish_max_iter: int = 60, shift=None) -> CoulombCertificate:
    """A backward-error certificate of a given answer (v (m,), u (5n,) or None for Hᵀv + w,
    r (5n,); or one result object) to the physical problem, e.g. one written by Siconos: ŝ :=
    ``shift`` (n,; the solver's own, e.g. ``CoulombDigits.shift``) or by default Φ(u); the
    candidate (v, u + ŝ e_N, r) proven for the convex problem with w_N + ŝ `rfverify.certify`, which polishes it where it does not prove itself), and δ bounded
    (:mod:`.backward`)."""
    from ..verify.certification import certify
    from ..solver import posed

    t0 = time.perf_counter()
    digits = validate_digits(digits)
    problem = posed(problem, as_stored)
    if shift is None and hasattr(v, "shift"):
        shift = v.shift
    v, u, r = _solution(problem, v, u, r)
    shifted = shifted_problem(problem, phi(problem, u) if shift is None else _checked_shift(problem, shift))
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(v)) and np.all(np.isfinite(r))):
        from ..errors import InvalidProblemError

        raise InvalidProblemError("solution", "contains NaN or Inf", fix="certify a finite solution")
    u_inner = (Dyadic.from_float(u) + Dyadic.from_float(offsets(shifted)) - Dyadic.from_float(offsets(problem))).nearest()
    inner = certify(shifted, v, u_inner, r, digits=digits, relative=relative, progress=progress,
                    time_limit=time_limit, polish_max_iter=polish_max_iter)
    cert = coulomb_certificate(problem, shifted, inner, v, u_inner, r, digits, _scales(problem), relative, u_phys=u)
    cert.seconds = time.perf_counter() - t0
    return cert


def start_shift(problem: Problem, start) -> np.ndarray | None:
    """The outer iteration's first shift from ``start``: None (0, the relaxation's answer); an
    array of n finite entries ≥ 0 (one per contact, in the data's units of velocity); or a result
    with a ``shift`` (a :class:`CoulombSolution` or :class:`CoulombDigits` of this problem)."""
    if start is None:
        return None
    s = _checked_shift(problem, getattr(start, "shift", start), "start")
    if np.any(s < 0):
        k = int(np.argmin(s))
        raise InvalidArgumentError("start", f"has a negative shift on contact {k} ({s[k]:.3g}): a shift "
                                            "mu|u_T| + mu_r|u_R| is never negative",
                                   fix="pass the shift of an answer of this problem (e.g. Φ of its u), or None")
    return s


def _checked_shift(problem: Problem, shift, name: str = "shift") -> np.ndarray:
    s = np.asarray(shift, dtype=np.float64).ravel()
    if s.size != problem.n_contacts or not np.all(np.isfinite(s)):
        raise InvalidArgumentError(name, f"needs {problem.n_contacts} finite entries (one per contact), got "
                                         f"{s.size}{'' if np.all(np.isfinite(s)) else ' with NaN or Inf'}",
                                   fix="pass the shift the answer was solved with (CoulombDigits.shift), or None")
    return s


def _solution(problem: Problem, v, u, r):
    """(v, u, r) as float64 vectors from arrays or one result object (``v``); u None: the file's
    own u = Hᵀv + w (W r + q).  Sizes are checked by :func:`rfverify.certify` on the shifted
    problem, which names the field."""
    if u is None and r is None and hasattr(v, "v"):
        v, u, r = v.v, getattr(v, "u", None), getattr(v, "r", None)
    if v is None or r is None:
        from ..errors import InvalidProblemError

        raise InvalidProblemError("solution", "needs v and r", fix="pass (v, u, r) or a result object")
    v, r = np.asarray(v, dtype=np.float64).ravel(), np.asarray(r, dtype=np.float64).ravel()
    if r.size != 5 * problem.n_contacts or v.size != problem.n_dofs:
        from ..errors import InvalidProblemError

        raise InvalidProblemError("solution", f"has v of {v.size} and r of {r.size} entries, the problem needs "
                                              f"{problem.n_dofs} and {5 * problem.n_contacts}",
                                  fix="certify a solution of this problem")
    u = physical_velocity(problem, v, r) if u is None else np.asarray(u, dtype=np.float64).ravel()
    if u.size != r.size:
        from ..errors import InvalidProblemError

        raise InvalidProblemError("solution.u", f"has {u.size} entries, the problem needs {r.size}",
                                  fix="certify a solution of this problem")
    return v, u, r
