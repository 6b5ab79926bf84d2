"""Certification of a float64 solution: a proof of its correct digits (DESIGN §6).

:func:`certify` proves a lower bound on the correct significant digits of a given solution
(v, u, r) of the convex relaxation:

1. If the solution carries its extended-precision point (a :class:`rfverify.DigitsSolution`,
   or a solution file written by ``solve --digits --out``), the bound is evaluated there.
2. Otherwise an extended-precision point near the solution set is computed (a double solve,
   then Algorithm 1 in double-double, as in the k-digit path), and the bound at that point is
   carried to the candidate by the triangle inequality.

The bound (:mod:`rfverify.proof.bound`) is evaluated rigorously: exact dyadic arithmetic for
the point's residuals and cone membership, verified floating point for the norms of M⁻¹.
What it assumes: the problem is the convex relaxation with M := (M + Mᵀ)/2 exactly, or with M
as stored (``as_stored=True``; the verdict names which, and a proof of (M + Mᵀ)/2 of an
unsymmetric M also states the digits for the stored equations), and the data are the float64
numbers in the file.  What it does not prove: anything about the physical (De Saxcé)
problem, or about r where r is not unique.

``cross_check=True`` also runs the independent mpmath reference (DESIGN §5) and reports the
digits of agreement with it: a second opinion, not part of the proof.
"""

from __future__ import annotations

import math
import time

import mpmath
import numpy as np

from ..errors import InvalidProblemError, require_time_limit
from .digits import DOUBLE_SETTINGS, solve_on_face
from .driver import ProofDriver
from .extend import extend
from .prepare import start_from
from ..model.problem import SPACEDIM, Problem
from ..proof import FLOAT64_DIGITS, Point, ProofContext, validate_digits
from .certificate import Certificate, candidate_point, certificate_from_proof
from ..compilation import compile_extended_in_background


def local_velocity(problem: Problem, r) -> np.ndarray:
    """u = (W + Wᵀ)/2 r + q of a local problem, rounded once to nearest from the exact value."""
    from ..proof.dyadic import Dyadic
    from ..proof.local import LocalExact

    return LocalExact(problem).u_of(Dyadic.from_float(r)).nearest()


def _solution_arrays(problem: Problem, v, u, r):
    if u is None and r is None and hasattr(v, "v"):
        v, u, r = v.v, getattr(v, "u", None), getattr(v, "r", None)
    if v is None or r is None:
        raise InvalidProblemError("solution", "needs v and r", fix="pass (v, u, r) or a result object")
    v = np.asarray(v, dtype=np.float64).ravel()
    r = np.asarray(r, dtype=np.float64).ravel()
    if v.size != problem.n_dofs:
        raise InvalidProblemError("solution.v", f"has {v.size} entries, the problem needs {problem.n_dofs}",
                                  fix="certify a solution of this problem")
    if r.size != SPACEDIM * problem.n_contacts:
        raise InvalidProblemError("solution.r", f"has {r.size} entries, the problem needs "
                                                f"{SPACEDIM * problem.n_contacts}",
                                  fix="certify a solution of this problem")
    if u is None:
        u = local_velocity(problem, r) if problem.local is not None else problem.H.T @ v + problem.w
    u = np.asarray(u, dtype=np.float64).ravel()
    if u.size != SPACEDIM * problem.n_contacts:
        raise InvalidProblemError("solution.u", f"has {u.size} entries, the problem needs "
                                                f"{SPACEDIM * problem.n_contacts}",
                                  fix="certify a solution of this problem")
    return v, u, r


def certify(problem: Problem, v, u=None, r=None, *, digits: int = 10, point: Point | None = None,
            cross_check: bool = False, dps: int = 50, polish_max_iter: int = 60,
            relative: bool = False, progress=None, as_stored: bool | None = None,
            time_limit: float | None = None) -> Certificate:
    """Prove how many significant digits of the float64 solution are correct.

    Example
    -------
    >>> import rfverify
    >>> p = rfverify.load("bundled:chute")
    >>> cert = rfverify.certify(p, rfverify.solve(p, tol=1e-8), digits=5)
    >>> cert.status, cert.digits                    # doctest: +SKIP
    (<Status.CERTIFIED: 'Certified'>, {'v': 6.0, 'u': 5.1, 'Hr': 6.0, 'r': 5.7})

    Parameters
    ----------
    problem : Problem
    v, u, r : arrays (m,), (5n,), (5n,), or one object with attributes ``v, u, r`` (a
        :class:`SolveResult`, :class:`DigitsSolution`, :class:`StoredSolution`) passed as
        ``v``.  A missing u is taken as Hᵀv + w.
    digits : int
        Requested digits, 1 … 15 (a float64 carries at most 15.95).
    point : Point, optional
        The extended-precision point to bound at (default: the object's ``point`` if it has
        one, else a warm polish from the candidate).
    cross_check : bool
        Also run the independent reference at ``dps`` digits (at least 34) and report agreement.
    relative : bool
        Demand relative digits for every quantity: a quantity whose exact value may be zero is
        then not certified (instead of being bounded against its data scale, DESIGN §6.3).
    time_limit : float, optional
        Seconds for the search for a proof point (the double solve and each extended
        iteration check it); when it runs out the best proof reached is returned, with status
        MaxTime if that falls short of ``digits``.
    as_stored : bool, optional
        True: prove the digits of the solution of the equations with M exactly as stored;
        False: with (M + Mᵀ)/2; None (default): what ``problem.equations`` says (symmetrised
        unless the problem came from :meth:`Problem.stored_equations`).  A proof of
        (M + Mᵀ)/2 of an unsymmetric M also states the digits for the stored equations.

    Without ``point``, the candidate itself is tried first as the proof point (exact or
    near-exact answers certify at O(nnz) cost, DESIGN §6.6); only if that does not certify is
    an extended-precision point computed.

    Returns
    -------
    Certificate
    """
    t0 = time.perf_counter()
    digits = validate_digits(digits)
    require_time_limit(time_limit)
    from ..solver import posed

    problem = posed(problem, as_stored)
    if point is None and hasattr(v, "point") and u is None and r is None:
        point = v.point
    from ..proof import Point

    if point is not None and not isinstance(point, Point):
        from ..errors import InvalidArgumentError

        raise InvalidArgumentError("point", f"is a {type(point).__name__}, not an rfverify.proof.Point",
                                   fix="pass the .point of a solve_to_digits result, or read_point(FILE), or None")
    if cross_check and not (isinstance(dps, (int, np.integer)) and dps >= 34):
        from ..errors import InvalidArgumentError

        # a reference at 1 digit 'agreed' with the answer to -13 digits: it must outdo float64 by far
        raise InvalidArgumentError("dps", f"is {dps!r}; the cross-check's reference needs at least 34 digits",
                                   fix="pass dps=50 (the default) or any whole number ≥ 34")
    v, u, r = _solution_arrays(problem, v, u, r)
    from ..model.scaling import in_scaled_units
    from .certificate import scaled_point, unscaled_certificate

    def in_scaled(scaled, scaling):
        xs = [scaling.scale(name, x) for name, x in (("v", v), ("u", u), ("r", r))]
        sp_ = scaled_point(point, scaling)
        if all(x is not None for x in xs) and (point is None or sp_ is not None):
            # Data beyond float64's safe range: proven in exactly scaled units (DESIGN §6.4).
            return certify(scaled, *xs, digits=digits, point=sp_, cross_check=False, polish_max_iter=polish_max_iter,
                           relative=relative, progress=progress, time_limit=time_limit)
        (progress or (lambda msg: None))("the candidate cannot be scaled exactly into float64's safe range: "
                                         "proven in the problem's own units")
        return None

    def unscaled(cert, scaled, scaling):
        cert = unscaled_certificate(cert, scaling)
        if cross_check:
            cert.cross_check = reference_agreement(problem, v, u, r, dps=dps)
        cert.seconds = time.perf_counter() - t0
        return cert

    cert = in_scaled_units(problem, in_scaled, unscaled)
    if cert is not None:
        return cert
    say = progress or (lambda msg: None)
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(u)) and np.all(np.isfinite(r))):
        return Certificate(digits, False, "not certified: the solution contains NaN or Inf",
                           seconds=time.perf_counter() - t0)
    ctx = ProofContext(problem)
    deadline = None if time_limit is None else t0 + time_limit
    if point is not None:
        proof, extra = ctx.prove(point, v, u, r, digits, relative=relative), {"point_source": "given"}
    else:
        proof, point, extra = _own_proof(problem, ctx, v, u, r, digits, polish_max_iter, say, relative, deadline,
                                         time_limit)
    cert = certificate_from_proof(ctx.with_companion(proof, point, v, u, r), point, extra)
    if cross_check:
        say(f"cross-check: independent reference at {dps} digits")
        cert.cross_check = reference_agreement(problem, v, u, r, dps=dps)
    cert.seconds = time.perf_counter() - t0
    return cert


def _own_proof(problem, ctx, v, u, r, digits, polish_max_iter, say, relative, deadline, time_limit):
    """(proof, point, extra): the candidate itself as the proof point, and where that does not
    certify, a computed point near the solution set (:func:`_polish_and_prove`), the better kept."""
    own = candidate_point(v, r)
    proof = ctx.prove(own, v, u, r, digits, relative=relative)
    say(f"the candidate itself as the proof point: {proof.summary()}")
    from ..solver import has_zero_data

    # f = w = 0: the answer is exactly 0, and no computed point proves more than the candidate does
    if proof.certified or not ctx.hypotheses_proven or has_zero_data(problem):
        return proof, own, {"point_source": "the candidate itself"}
    polished, at, info = _polish_and_prove(problem, ctx, v, u, r, digits, polish_max_iter, say, relative,
                                           deadline, time_limit)
    # Keep the better proof: a computed point can bound the candidate worse than itself.
    if ProofDriver.score(polished) >= ProofDriver.score(proof):
        return polished, at, dict(info)
    limit = {"time_limit": info["time_limit"]} if "time_limit" in info else {}  # the search was cut short
    return proof, own, {"point_source": "the candidate itself (better than the computed point)", **limit}


def _polish_and_prove(problem, ctx, v, u, r, digits, max_iter, say, relative=False, deadline=None, time_limit=None):
    """Find an extended-precision point near the solution set and carry its bound to the
    candidate.  The point comes from the k-digit machinery — a double solve, then Algorithm 1
    in double-double — not from the candidate itself: a rounded candidate sits on (or just
    outside) the cone boundaries, and an infeasible interior-point run shrinks its primal
    residual and μ at the same rate, so a start pushed into the cones from it never gets its
    residual below the cone margins (measured on the bundled Chute: ratio 5 at every step)."""
    from ..extended.data import ExtendedData
    from ..extended.system import choose_backend
    from ..solver import solve

    compile_extended_in_background()  # on a cold numba cache: the other core compiles the extended kernels
    limit = {} if deadline is None else {"time_limit": max(deadline - time.perf_counter(), 1e-3)}
    double = solve(problem, method="auto", tol=1e-10, **DOUBLE_SETTINGS, **limit)
    data = ExtendedData(problem)
    system = choose_backend(data)
    driver = ProofDriver(ctx, data, digits, target=(v, u, r), progress=say, relative=relative, deadline=deadline)
    say(f"extended point: double solve {double.status} in {double.nit} iterations, then double-double "
        f"({system.name})")
    out = extend(data, start_from(data, double), driver, system, max_iter=max_iter, say=say)
    face = None
    if not driver.certified and not driver.timed_out:  # no interior (a self-stress): solve on its face
        face = solve_on_face(problem, ctx, driver, digits, relative, say, deadline,
                             dict(method="auto", tol=1e-10, extended_max_iter=max_iter), depth=0)
    _, proof, point, _ = driver.best
    info = {"point_source": "double solve + " + out.point_source, "double_iterations": int(double.nit),
            **out.summary(), "proof_attempts": driver.attempts, "proven_at": driver.proven_at()}
    if face is not None:
        if face.pop("_point", None) is point:
            info["point_source"] = "the problem reduced to the face of its self-stresses (DESIGN §6.8), lifted back"
        info["face"] = face
    if driver.timed_out and not proof.certified:
        info["time_limit"] = time_limit
    return proof, point, info


def reference_agreement(problem: Problem, v, u, r, dps: int = 50) -> dict:
    """Digits of agreement with the independent mpmath reference (information, not proof):
    −log10(‖x − x_ref‖∞ / s) for v, u, Hr and r, s the larger of ‖x_ref‖∞ and the quantity's
    data scale (‖M⁻¹f‖∞, ‖HᵀM⁻¹f + w‖∞, ‖f‖∞, ‖f‖∞/max_k‖h_k‖₂: where the exact value is 0, as u
    of a sphere at rest, a relative measure would compare rounding errors with each other; for a
    local file ‖q‖∞ and ‖q‖∞ / max_k W_kk, the certificate's own data scales)."""
    import reference

    names = ("v", "u", "r")
    target = problem
    if problem.local is not None:  # the file's own local problem, not its lifting
        target = local_reference_problem(problem)
        if target is None:
            return {"note": "no reference for a local problem whose W is not definite on its nonzero rows",
                    "dps": dps}
        names = ("u", "r")
    try:
        ref = reference.solve(target, dps=dps)
    except ArithmeticError as exc:  # its own linear algebra (e.g. along a self-stress): an opinion it cannot give
        return {"reference_status": "BrokeDown", "note": f"the reference broke down: {exc}", "dps": dps}
    out = {"reference_status": ref.status, "reference_iterations": ref.nit, "dps": dps}
    if not ref.success:
        out["note"] = f"the reference did not converge ({ref.message})"
        return out
    if problem.local is not None:
        from ..proof.local import local_data_scales

        floor = local_data_scales(problem)  # ‖q‖∞ for u, ‖q‖∞ / max_k W_kk for r
        with mpmath.workdps(2 * dps):
            for name in names:
                x, xr = (u, ref.u) if name == "u" else (r, ref.r)
                err = max((abs(mpmath.mpf(float(a)) - b) for a, b in zip(x, xr)), default=mpmath.mpf(0))
                scale = max(max((abs(b) for b in xr), default=mpmath.mpf(0)), mpmath.mpf(float(floor[name])))
                out[f"digits_{name}"] = _agreement(err, scale)
        return out
    from ..model.measures import data_scales

    data = data_scales(problem)  # a quantity whose exact value is (near) 0 is compared at its data scale
    floor = {"v": data.v_free, "u": data.u_free, "r": data.r, "Hr": data.f}
    with mpmath.workdps(2 * dps):
        for name, x in (("v", v), ("u", u), ("r", r)):
            xr = getattr(ref, name)
            err = max((abs(mpmath.mpf(float(a)) - b) for a, b in zip(x, xr)), default=mpmath.mpf(0))
            scale = max(max((abs(b) for b in xr), default=mpmath.mpf(0)), mpmath.mpf(floor[name]))
            out[f"digits_{name}"] = _agreement(err, scale)
        # H r_ref in the reference's arithmetic: along a self-stress r_ref can be huge (5.6e18 on a
        # wedge) while H r_ref is not, and a float64 product of it loses Hr's digits
        Hc = problem.H.tocsc()
        Hr_ref = [mpmath.mpf(0)] * Hc.shape[0]
        for j in range(Hc.shape[1]):
            for k in range(Hc.indptr[j], Hc.indptr[j + 1]):
                Hr_ref[Hc.indices[k]] += mpmath.mpf(float(Hc.data[k])) * ref.r[j]
        Hr = problem.H @ r
        err = max((abs(mpmath.mpf(float(a)) - b) for a, b in zip(Hr, Hr_ref)), default=mpmath.mpf(0))
        out["digits_Hr"] = _agreement(err, max(max((abs(b) for b in Hr_ref), default=mpmath.mpf(0)),
                                               mpmath.mpf(floor["Hr"])))
    return out


def local_reference_problem(problem: Problem):
    """The local problem u = W r + q as a global one the reference can read *exactly*:
    M = W_FF, H = W_F: (F = rows of W with a nonzero diagonal), f = 0, w = q, so that
    v = W_FF⁻¹ W_F: r = r_F and u = Hᵀv + q = W r + q with no factorisation of W.  Needs W
    definite on F (None otherwise).  W is taken as (W + Wᵀ)/2 in float64 (information only)."""
    import types

    import scipy.sparse as sp

    W = sp.csr_matrix(problem.local.W)
    Ws = (W * 0.5 + W.T * 0.5).tocsr()
    F = np.flatnonzero(Ws.diagonal() != 0)
    M = Ws[F][:, F].tocsc()
    try:
        if np.linalg.eigvalsh(M.toarray())[0] <= 0:
            return None
    except np.linalg.LinAlgError:
        return None
    return types.SimpleNamespace(M_sym=M, H=Ws[F].tocsc(), f=np.zeros(F.size), w=np.asarray(problem.local.q),
                                 mu=np.asarray(problem.mu), mu_r=np.asarray(problem.mu_r))


def _agreement(err, scale):
    err, scale = float(err), float(scale)
    if scale == 0:
        return None
    if err == 0:
        return FLOAT64_DIGITS
    return min(FLOAT64_DIGITS, -math.log10(err / scale))
