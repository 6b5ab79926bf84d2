"""The double-precision (mixed-precision) production solver: :func:`solve`."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
import scipy.sparse as sp

from ..compilation import compile_seconds
from ..model.lifting import KIND_NAMES
from ..model.measures import Arithmetic, MeasureData, data_scales, data_scales_from_arrays, measures
from ..model.problem import SPACEDIM, Problem
from .cones import ProductCone
from .in_units import returned_verdict
from .presolve import presolve
from .result import (AUTO_LAST_RESORT, AUTO_SCHUR_MIN_CONTACTS, AUTO_SCHUR_MIN_FILL, AUTO_SEQUENCE, AUTO_SEQUENCE_LARGE, METHODS,
                     OPTIONAL_METHODS, TRACE_FIELDS, IterationInfo, Settings, SolveResult, Status,
                     method_unavailable, renamed_settings)

__all__ = ["solve", "posed", "Settings", "SolveResult", "Status", "METHODS", "IterationInfo", "auto_sequence", "body_fill"]


def auto_sequence(n_contacts: int, fill=None) -> tuple:
    """The forms ``method="auto"`` tries, in order, on a problem of ``n_contacts`` contacts:
    ``AUTO_SEQUENCE_LARGE`` (schur first) when ``n_contacts ≥ AUTO_SCHUR_MIN_CONTACTS`` and the
    factorisation's ``fill`` (:func:`body_fill`; a number, or a callable that computes it, called
    only when the problem is that large) is at least ``AUTO_SCHUR_MIN_FILL``; else
    ``AUTO_SEQUENCE`` (jqinv first).  The same choice with or without the optional CHOLMOD, which
    only makes schur faster (:func:`rfverify.engines.factor.schur_engine`).  The names and
    thresholds are declared in :mod:`rfverify.solver.result`."""
    if n_contacts < AUTO_SCHUR_MIN_CONTACTS:
        return AUTO_SEQUENCE
    fill = fill() if callable(fill) else fill
    return AUTO_SEQUENCE_LARGE if fill is not None and fill >= AUTO_SCHUR_MIN_FILL else AUTO_SEQUENCE


def body_fill(problem: Problem) -> float:
    """Σ(column count)² per contact of the Cholesky factor, under QDLDL's AMD ordering (the same on
    every install, whatever engine factors), of the body graph: one node per body (6 consecutive
    dofs when every block of M lies in such a group, the rigid-body convention; else one per
    block of M), an edge per pair of bodies sharing a contact.  Proportional to the flops of
    factoring any form of the problem (every form's matrix has this graph, blown up by the dofs
    per body), at a small fraction of their cost (~1 ms at 10³ contacts, ~1 s at 10⁵)."""
    m = problem.n_dofs
    labels = problem.blocks.labels
    group = np.arange(m) // 6
    first = np.full(problem.blocks.count, m)
    np.minimum.at(first, labels, np.arange(m))
    rigid = m % 6 == 0 and np.all(group == first[labels] // 6)
    node = group if rigid else labels
    HT = problem.H.T.tocoo()
    C = sp.csr_matrix((np.ones(HT.nnz), (HT.row // 5, node[HT.col])), shape=(problem.n_contacts, int(node.max()) + 1))
    C.data[:] = 1.0
    A = (C.T @ C).tocsc()
    used = np.flatnonzero(A.diagonal() > 0)
    A = A[used][:, used]
    A = (A + sp.diags(np.asarray(A.sum(axis=1)).ravel() + 1.0)).tocsc()  # diagonally dominant: SPD
    import qdldl

    L = qdldl.Solver(A).factors()[0].tocsc()  # strictly lower: the unit diagonal is not stored
    counts = np.diff(L.indptr).astype(np.float64) + 1.0
    return float(np.sum(counts * counts)) / max(problem.n_contacts, 1)


def solve(problem: Problem, method: str = "auto", tol: float = 1e-10, max_iter: int = 100,
          keep_iterates: bool = False, callback=None, *, as_stored: bool | None = None,
          **options) -> SolveResult:
    """Solve a rolling-friction problem (its convex relaxation, DESIGN §1) with Algorithm 1, or
    hand it to a peer solver, and judge the answer by rfverify's criterion (DESIGN §4.5).

    Example
    -------
    >>> import rfverify
    >>> p = rfverify.load("bundled:chute")
    >>> res = rfverify.solve(p, tol=1e-10)
    >>> res.status, res.criterion <= 1e-10          # doctest: +SKIP
    (<Status.SOLVED: 'Solved'>, True)
    >>> res.v.shape, res.u.shape, res.r.shape       # velocities, contact velocities, reactions
    ((768,), (20,), (20,))

    For digits that are *proven* right, use :func:`rfverify.solve_to_digits` instead.

    Parameters
    ----------
    problem : Problem
        From :func:`rfverify.load` or :meth:`Problem.from_arrays`.  A problem read from a local
        file is solved through a lifting to global form and its answer judged on the file's own
        u = W r + q.
    method : {"auto", "jqinv", "qp2", "reduced", "reduced_factored", "noscaling", "schur", "clarabel", "siconos"}
        The linear system Algorithm 1 factors at each iteration (DESIGN §4.2).  ``auto`` (default)
        picks by the problem's size and fill — ``schur`` (the dof-space Schur complement, factored
        by CHOLMOD's supernodal Cholesky) on large problems whose factor fills in (granular piles
        and beds, random problems), ``jqinv`` otherwise — and tries the next form while one
        stalls, and after the last one ``jqinv`` with the paper's σ rule (:data:`AUTO_LAST_RESORT`;
        not where ``sigma_rule`` is given; its answer is returned only if it is Solved);
        ``extras["attempts"]`` lists the runs and ``method`` names the one returned.
        ``clarabel`` hands the same convex problem to Clarabel; ``siconos`` runs the paper's own
        GRFC3D_IPM in a child process (it needs ``bash benchmarks/peers/siconos/build.sh`` and
        ``RFVERIFY_SICONOS``).  Both peers are judged by the same criterion.
    tol : float
        Solved means the criterion of the returned (v, u, r) is at most ``tol`` (dimensionless;
        about 1e-16 is the floor double precision reaches).  The paper's pinfeas, dinfeas and μ
        are reported beside it.
    max_iter : int
    keep_iterates : bool
        Store every iterate in ``extras["iterates"]`` (for :func:`rfverify.diagnose`).  The
        iterates are those of one system, so this also solves the problem unsplit
        (``split_components=False``): the answer can differ, within the tolerance, from a split
        solve's (on the bundled Chute by 6.9e-7 in v); and reactions in units that differ from
        contact to contact are then not brought together (the iterates are the problem's own).
    as_stored : bool, optional
        True: solve the equations with an unsymmetric M exactly as stored; False: with
        (M + Mᵀ)/2, the convention of Siconos and FCLIB; None (default): the problem object's own
        choice (symmetrised unless it came from :meth:`Problem.stored_equations`).  The two differ
        only for an unsymmetric M.  Not for the peers, nor for a local file with an unsymmetric W.
    callback : callable, optional
        ``callback(info)`` once per iteration; returning True stops the run (status Stopped, its
        best iterate returned).  Not for the peers.
    **options
        Solver settings (:class:`Settings`): ``time_limit`` (seconds; status MaxTime with the
        best iterate), ``verbose=True`` (one printed row per iteration), and the algorithm's
        knobs (``sigma_rule``, ``refine_max``, ...).

    Returns
    -------
    SolveResult
        ``v`` (m,), ``u`` = Hᵀv + w (5n,), ``r`` (5n,) in the file's units and layout (FCLIB: 5
        per contact, N, T1, T2, R1, R2), with ``status``, ``message``, ``criterion``, ``nit``,
        ``time``, ``trace`` (docs/RESULTS.md).  Ctrl-C during the iterations returns the best
        iterate so far with status Stopped and ``extras["interrupted"]``.
    """
    problem = posed(problem, as_stored, method)
    options = renamed_settings(options)
    from ..model.scaling import in_contact_units, in_scaled_units
    from .in_units import in_own_contact_units, unscaled_result

    again = lambda sp_, _: solve(sp_, method, tol, max_iter, keep_iterates, callback, **options)  # noqa: E731
    # (iterates kept are the lifted variables of the problem solved: it is then solved as given)
    scaled = None if keep_iterates else in_contact_units(problem, again, in_own_contact_units)
    if scaled is None:
        scaled = in_scaled_units(problem, again, unscaled_result)
    if scaled is not None:
        return scaled
    if has_zero_data(problem):
        return _zero_data_result(problem, method, tol, max_iter, options)
    c0 = compile_seconds()
    result = _solve(problem, method, tol, max_iter, keep_iterates, callback, **options)
    result.timings["compile"] = compile_seconds() - c0  # numba's, on a cold start (included in total)
    if not result.success and tol < DOUBLE_REACH:
        hint = (f"tol = {tol:g} is below what double precision can reach (the criterion's own rounding is "
                f"about 1e-16; this run reached {result.criterion:.2e}): for more accuracy use --digits K "
                f"(rfverify.solve_to_digits), which continues in extended precision and proves K digits")
        result.extras["hint"] = hint
        result.message = f"{result.message}; {hint}"
    return result


DOUBLE_REACH = 1e-15
"""Tolerances below this are out of double precision's reach on most problems (the criterion's
own rounding is about 1e-16): a run that misses one says so and points to the k-digit path."""


def has_zero_data(problem: Problem) -> bool:
    """f = 0 and w = 0 (q = 0 for a local file): v = u = r = 0 is the answer, exactly."""
    data = problem.local.q if problem.local is not None else np.concatenate((problem.f, problem.w))
    return not np.any(data)


def _zero_data_result(problem, method, tol, max_iter, options) -> SolveResult:
    """f = 0 and w = 0 (q = 0): v = 0, u = 0, r = 0 is a solution, and v, u, Hr are unique
    (vᵀMv = vᵀHr = uᵀr = 0 forces v = 0).  Returned exactly, without iterating (an
    interior-point run has no scale to converge to there)."""
    from ..errors import InvalidArgumentError

    if method not in METHODS:
        raise ValueError(f"method {method!r} is not one of {', '.join(METHODS)}")
    unknown = set(options) - set(Settings.accepted())
    if unknown:
        raise TypeError(f"unknown solver option(s): {', '.join(sorted(unknown))}; valid: {', '.join(Settings.names())}")
    if method_unavailable(method) is not None:
        raise InvalidArgumentError("method", method_unavailable(method).split("; fix: ")[0],
                                   fix=f"{OPTIONAL_METHODS[method][1]}, or use method='auto'")
    settings = Settings(tol=tol, max_iter=max_iter, **options)
    m, k = problem.n_dofs, SPACEDIM * problem.n_contacts
    v, u, r = np.zeros(m), np.zeros(k), np.zeros(k)
    final = measures(problem, v, u, r, "longdouble")
    trace = {key: np.zeros(0) for key in TRACE_FIELDS}
    return SolveResult(v=v, u=u, r=r, status=Status.SOLVED,
                       message="f = 0 and w = 0: v = 0, u = 0, r = 0 is the solution (exact; no iteration needed)",
                       nit=0, measures=final, pinfeas=0.0, dinfeas=0.0, mu=0.0, trace=trace,
                       timings={"total": 0.0, "compile": 0.0}, method=method, settings=settings,
                       presolve={}, extras={"zero_data": True})


def _counting(callback, components: int):
    """``callback`` receiving infos that say how many components the problem was split into."""
    if callback is None or components == 1:
        return callback
    return lambda info: callback(dataclasses.replace(info, components=components))


def posed(problem: Problem, as_stored: bool | None, method: str | None = None) -> Problem:
    """``problem`` posing the equations ``as_stored`` asks for (None: its own), refused where
    they cannot be solved: the peers (Clarabel, Siconos) take (M + Mᵀ)/2 only, and a local file
    is solved through a symmetric lifting of its W."""
    from ..errors import InvalidArgumentError

    if as_stored is not None:
        problem = problem.stored_equations(bool(as_stored))
    if not problem.as_stored:
        return problem
    if method in ("clarabel", "siconos"):
        raise InvalidArgumentError("method", f"{method} solves (M + Mᵀ)/2 only, not an unsymmetric M as stored",
                                   fix="drop --as-stored (as_stored=False), or use an Algorithm 1 method")
    if problem.local is not None:
        raise InvalidArgumentError("as_stored", "is not available for a local file whose W is unsymmetric: the "
                                                "double solver works on a symmetric lifting W = HᵀH",
                                   fix="drop --as-stored: the answer is then proven for (W + Wᵀ)/2 and the "
                                       "verdict says so")
    return problem


def judged_on_the_file(problem: Problem, result: SolveResult) -> SolveResult:
    """A local file's answer judged on the file: u := W r + q of the file's W (not the
    lifting's Hᵀv + w), and the criterion of (v, u, r) — whose velocity residual
    u − (Hᵀv + w) is then the gap between W and its lifting — decides the status.  A run
    Solved on the lifting but not on the file is downgraded, and the message says why."""
    u = problem.local.velocity(result.r)
    final = measures(problem, result.v, u, result.r, "longdouble")
    tol = result.settings.tol
    lift = problem.provenance.get("lift") or problem.provenance.get("lifted") or {}
    if result.status is Status.SOLVED and not final.max <= tol:
        status = Status.ALMOST_SOLVED if final.max <= result.settings.almost_factor * tol \
            else Status.INSUFFICIENT_PROGRESS
        dropped = lift.get("dropped")
        lam = float(lift.get("min_eigenvalue", 0.0))
        why = (f"; the lifting dropped {dropped} eigenvalue(s) of W (smallest {lam:.2e}"
               + ("): W is not positive semidefinite as stored" if lam < 0 else ")")) if dropped else ""
        # two measures of one point, named: the lifting's (which the run met) and the file's
        message = (f"solved on the lifting (criterion there {result.criterion:.2e}), but the file's own problem "
                   f"u = W r + q has criterion {final.max:.2e} > tol ({final.worst()}){why}")
    else:  # the file's criterion is the one stated, and decides as it does for any answer
        status, message = returned_verdict(*result.extras.get("run_verdict", (result.status, result.message)),
                                           final, result.settings)
    return dataclasses.replace(result, u=u, measures=final, status=status, message=message)


def _solve(problem: Problem, method: str, tol: float, max_iter: int, keep_iterates: bool, callback,
           **options) -> SolveResult:
    if method not in METHODS:
        raise ValueError(f"method {method!r} is not one of {', '.join(METHODS)}")
    missing = method_unavailable(method)
    if missing is not None:
        from ..errors import InvalidArgumentError

        raise InvalidArgumentError("method", missing.split("; fix: ")[0],
                                   fix=f"{OPTIONAL_METHODS[method][1]}, or use method='auto'")
    unknown = set(options) - set(Settings.accepted())
    if unknown:
        raise TypeError(f"unknown solver option(s): {', '.join(sorted(unknown))}; "
                        f"valid: {', '.join(Settings.names())}")
    from ..errors import InvalidArgumentError

    if callback is not None and not callable(callback):
        raise InvalidArgumentError("callback", f"is {callback!r}, not callable",
                                   fix="pass a function callback(info) -> bool, or None")
    if not isinstance(keep_iterates, (bool, np.bool_)):
        raise InvalidArgumentError("keep_iterates", f"is {keep_iterates!r}; it must be True or False",
                                   fix="pass keep_iterates=True or keep_iterates=False")
    if keep_iterates:
        options["split_components"] = False
    settings = Settings(tol=tol, max_iter=max_iter, **options)
    if method == "auto":
        return _solve_in_turn(problem, settings, keep_iterates, callback, options)
    return _solve_form(problem, method, settings, keep_iterates, callback)


def _on_the_file(problem: Problem, result: SolveResult) -> SolveResult:
    """A local file's answer judged on the file (per form: auto then chooses by that verdict)."""
    return judged_on_the_file(problem, result) if problem.local is not None else result


def _solve_form(problem: Problem, method: str, settings: Settings, keep_iterates: bool, callback) -> SolveResult:
    """One form of Algorithm 1, or a peer, on ``problem`` (checked by :func:`_solve`), its
    answer judged on the problem as read."""
    t0 = time.perf_counter()
    if method == "clarabel":
        if callback is not None:
            from ..errors import InvalidArgumentError

            raise InvalidArgumentError("callback", "is not available for the Clarabel peer",
                                       fix="use an Algorithm 1 method (jqinv, qp2, ...)")
        from .clarabel_peer import solve_clarabel

        return _on_the_file(problem, solve_clarabel(problem, settings))
    if method == "siconos":
        if callback is not None:
            from ..errors import InvalidArgumentError

            raise InvalidArgumentError("callback", "is not available for the Siconos peer",
                                       fix="use an Algorithm 1 method (jqinv, qp2, ...)")
        from .siconos_peer import solve_siconos

        return _on_the_file(problem, solve_siconos(problem, settings))

    pre = presolve(problem, settings)
    lp, groups, v, presolve_info = pre.lifted, pre.groups, pre.v, pre.info
    M = problem.M_sym
    t_pre = time.perf_counter() - t0

    from . import ipm
    from .log import IterationPrinter

    printer = IterationPrinter(problem, method, settings, lp, components=len(groups)) if settings.verbose else None
    r_t = np.zeros(lp.nk, dtype=np.longdouble)
    z = np.zeros(lp.nz, dtype=np.longdouble)
    runs = []
    judges = [component_judge(problem, lp, dofs, rows, settings) for dofs, rows, *_ in groups]
    share = complementarity_share(problem, judges)
    for judge in judges:
        judge.share = share
    for index, (dofs, rows, zidx, cone_ids, n_c) in enumerate(groups):
        n3_c = int(np.sum(cone_ids < lp.n3))
        cones = ProductCone(n3_c, cone_ids.size - n3_c, compiled=settings.compiled_kernels)

        def describe(k, cone_ids=cone_ids):
            g = cone_ids[k]
            part = ("friction (N,T) cone", "rolling (N,R) cone", "normal cone")[lp.cone_part[g]]
            c = lp.cone_contact[g]
            return f"contact {c} {part} [{KIND_NAMES[lp.kinds[c]]} contact]"

        def held_by(k, side, cone_ids=cone_ids):
            return {"cone": int(cone_ids[k]), **lp.held_by(int(cone_ids[k]), side)}

        out = ipm.run(M[dofs][:, dofs].tocsc(), problem.f[dofs], lp.H_t[rows][:, dofs].tocsr(),
                      lp.w_t[rows], lp.J[rows][:, zidx].tocsr(), cones, n_c, method, settings,
                      judge=judges[index], describe_cone=describe,
                      keep_iterates=keep_iterates, callback=_counting(callback, len(groups)), component=index, t0=t0,
                      printer=printer, M_eq=problem.M[dofs][:, dofs].tocsc() if problem.as_stored else None,
                      held_by=held_by)
        for key in ("min_lam2_z_cone", "min_lam2_s_cone"):  # the component's cones -> the lifted problem's
            out.trace[key] = cone_ids[out.trace[key].astype(np.int64)]
        v[dofs] = out.v
        r_t[rows] = out.r_t
        z[zidx] = out.z
        runs.append(out)
        if out.status in (Status.STOPPED, Status.MAX_TIME):
            break  # the user's stop and the time limit hold for the whole solve

    run_status, run_message = _combined_status(runs, len(groups))
    v = np.asarray(v, dtype=np.float64)
    r = lp.r_from_lifted(np.asarray(r_t, dtype=np.float64))
    u = lp.u_from_v(v)
    # The verdict is about what is returned: the whole problem, rounded to float64.
    final = measures(problem, v, u, r, "longdouble")
    status, message = returned_verdict(run_status, run_message, final, settings)
    if len(runs) == 1:
        pinf, dinf, mu = runs[0].pinfeas, runs[0].dinfeas, runs[0].mu
    else:
        from .clarabel_peer import lifted_measures

        pinf, dinf, mu = lifted_measures(problem.M_eq, problem.f, lp.H_t, lp.w_t, lp.J, v, np.asarray(r_t, dtype=np.float64),
                                         np.asarray(z, dtype=np.float64), problem.n_contacts)
    timings = {k: sum(o.timings.get(k, 0.0) for o in runs) for k in ("factor", "solve")}
    timings["presolve"] = t_pre
    timings["total"] = time.perf_counter() - t0
    result = SolveResult(
        v=v, u=u, r=r, status=status, message=message, nit=max(o.nit for o in runs), measures=final,
        pinfeas=pinf, dinfeas=dinf, mu=mu, trace=max(runs, key=lambda o: o.nit).trace,
        timings=timings, method=method, settings=settings, presolve=presolve_info,
        extras={"factorisations": sum(o.factorisations for o in runs),
                "unregularised_factorisations": sum(o.unregularised_factorisations for o in runs),
                "longdouble_from": [o.longdouble_from for o in runs],
                "extended_from": [o.longdouble_from for o in runs],  # its name before issue 50, kept for callers
                "r_t": r_t, "z": z, "run_verdict": (run_status, run_message),
                "returned_iteration": [o.returned_iteration for o in runs],
                "interrupted": any(o.interrupted for o in runs),
                "n_cones": {"L3": lp.n3, "L1": lp.n1},
                "steps_held": [dict(held, component=c) if len(groups) > 1 else held
                               for c, o in enumerate(runs) for held in steps_held(lp, o.trace)],
                "component_runs": [{"status": o.status, "message": o.message, "nit": o.nit, "trace": o.trace}
                                   for o in runs] if len(groups) > 1 else [],
                "iterates": runs[0].iterates if keep_iterates else [],
                "active_dofs": groups[0][0] if keep_iterates else None},
    )
    result = _on_the_file(problem, result)
    if printer is not None:
        printer.summary(result)
    return result


def steps_held(lp, trace: dict) -> list[dict]:
    """Each step of a run's ``trace`` that a cone's boundary cut short (α < 1), in the problem's
    terms: [{"from_iteration" (the step from that iterate to the next), "alpha", "cone" (index
    in the lifted problem ``lp``), "contact", "part", "side"}] (``LiftedProblem.held_by``)."""
    rows = zip(trace["iter"], trace["alpha"], trace["step_cone"], trace["step_side"])
    return [{"from_iteration": int(k), "alpha": float(alpha), "cone": int(cone),
             **lp.held_by(int(cone), "zs"[int(side)])} for k, alpha, cone, side in rows if cone >= 0]


def _solve_in_turn(problem, settings, keep_iterates, callback, options) -> SolveResult:
    """``method="auto"``: the forms of :func:`auto_sequence` in turn, each from the standard start,
    while the previous one stalled or broke down (InsufficientProgress, NumericalError,
    AlmostSolved); Solved, a user stop, the iteration limit or the time limit end the sequence
    (the limits are the user's budget; the time limit holds for all runs together).  Returns
    the Solved run, else the one with the smallest criterion, with ``extras["attempts"]`` and
    a message naming what was tried."""
    t0 = time.perf_counter()
    attempts, results, unrun = [], [], None
    forms, why = _auto_choice(problem)
    runs = [(form, None) for form in forms]
    if "sigma_rule" not in options:  # the caller's σ rule is kept; else the last resort after a stall
        runs.append(AUTO_LAST_RESORT)
    for form, rule in runs:
        opts = dict(options) if rule is None else {**options, "sigma_rule": rule}
        left = None
        if settings.time_limit is not None:
            left = settings.time_limit - (time.perf_counter() - t0)
            if left <= 0 and results:
                unrun = attempt_words({"method": form, "sigma_rule": rule})
                break
            opts["time_limit"] = left = max(left, 1e-12)  # the first form runs, if only to its start
        res = _solve(problem, form, settings.tol, settings.max_iter, keep_iterates, callback, **opts)
        if left is not None and res.status is Status.MAX_TIME:  # the user's limit, not what was left of it
            res.message = res.message.replace(f"time limit of {left:g} s",
                                              f"time limit of {settings.time_limit:g} s (all forms together)")
        results.append(res)
        attempts.append({"method": form, "status": str(res.status), "criterion": res.criterion, "nit": res.nit,
                         "seconds": res.timings.get("total", float("nan")), **({"sigma_rule": rule} if rule else {})})
        if res.status in (Status.SOLVED, Status.STOPPED, Status.MAX_TIME, Status.MAX_ITERATIONS):
            break
    # the last resort's answer is returned only where it is Solved (its failure is only listed)
    best = next((r for r in results if r.success), None) or min(
        results[:len(forms)], key=lambda r: r.criterion if np.isfinite(r.criterion) else np.inf)
    if len(results) > 1:
        tried = "; ".join(f"{attempt_words(a)}: {a['status']} (criterion {a['criterion']:.2e})" for a in attempts)
        which = attempt_words(attempts[next(i for i, r in enumerate(results) if r is best)])
        best.message = f"auto returned {which} [{tried}]: {best.message}"
    if not best.success and (unrun or results[-1].status is Status.MAX_TIME) and \
            best.status not in (Status.STOPPED, Status.MAX_TIME):
        # the user's time limit ended the sequence, whichever form's answer is the best so far
        why_not = f"before {unrun} could start" if unrun else f"during {attempt_words(attempts[-1])}"
        best.message = (f"the time limit of {settings.time_limit:g} s (all forms together) ran out {why_not}; "
                        f"{best.message}")
        best.status = Status.MAX_TIME
    best.extras["attempts"] = attempts
    last = runs[-1] if len(runs) > len(forms) else None
    best.extras["auto"] = {"forms": list(forms), "why": why,
                           "last_resort": last and attempt_words({"method": last[0], "sigma_rule": last[1]})}
    if settings.time_limit is not None:  # its settings name the user's limit, not what was left of it
        best.settings = dataclasses.replace(best.settings, time_limit=settings.time_limit)
    best.timings["total"] = time.perf_counter() - t0
    return best


def attempt_words(attempt: dict) -> str:
    """An ``extras["attempts"]`` entry's form in words: "jqinv", or "jqinv (σ rule paper)" for
    :data:`AUTO_LAST_RESORT`."""
    rule = attempt.get("sigma_rule")
    return attempt["method"] + (f" (σ rule {rule})" if rule else "")


def _auto_choice(problem: Problem) -> tuple[tuple, str]:
    """(the forms ``auto`` tries on ``problem``, in order — :func:`auto_sequence`'s choice — and
    why, in words: the contact count and, on a large problem, the factor's fill per contact
    against the thresholds of :mod:`rfverify.solver.result`)."""
    n = problem.n_contacts
    contacts = f"{n} contact{'' if n == 1 else 's'}"
    if n < AUTO_SCHUR_MIN_CONTACTS:
        return auto_sequence(n), f"{contacts} < {AUTO_SCHUR_MIN_CONTACTS}"
    fill = body_fill(problem)
    forms = auto_sequence(n, fill)
    relation = "≥" if forms == AUTO_SEQUENCE_LARGE else "<"
    return forms, (f"{contacts} ≥ {AUTO_SCHUR_MIN_CONTACTS} with a factor fill of {fill:.0f} per contact "
                   f"{relation} {AUTO_SCHUR_MIN_FILL:g}")


def _combined_status(runs, n_groups):
    """Worst status over the components (a run cut short leaves the rest unsolved)."""
    if len(runs) == 1 and n_groups == 1:
        return runs[0].status, runs[0].message
    worst = max(runs, key=lambda o: _SEVERITY.index(o.status))
    bad = [o.message for o in runs if o.status is not Status.SOLVED]
    if len(runs) < n_groups:
        return worst.status, f"stopped after {len(runs)} of {n_groups} components: {worst.message}"
    return worst.status, (f"all {n_groups} components solved" if not bad
                          else f"{len(bad)} of {n_groups} components not solved; first: {bad[0]}")


_SEVERITY = [Status.SOLVED, Status.ALMOST_SOLVED, Status.MAX_ITERATIONS, Status.MAX_TIME, Status.STOPPED,
             Status.INSUFFICIENT_PROGRESS, Status.NUMERICAL_ERROR]


def component_judge(problem, lp, dofs, rows, settings, share: float = 1.0):
    """``judge(v, r̃)`` for one independent component: the measures of
    :mod:`rfverify.model.measures` on the component's data in the original variables (u = Hᵀv + w,
    r = P r̃, as returned: in float64), evaluated in the solver's residual precision.  Every
    ∞-norm measure of the whole problem is at most the largest of its components' (numerators
    are maxima, denominators grow); the complementarity |rᵀu|/E is not — its numerator sums
    over the components — so a component's is multiplied by ``share`` = ΣE_c/E
    (:func:`complementarity_share`): every component meeting tol then implies the whole problem
    does.  ``judge.energy`` is the component's E_c."""
    contacts = np.unique(lp.keep[rows] // SPACEDIM)
    cols = (SPACEDIM * contacts[:, None] + np.arange(SPACEDIM)).ravel()
    M_c = problem.M_eq[dofs][:, dofs].tocsc()
    H_c = problem.H[dofs][:, cols].tocsc()
    f_c, w_c = problem.f[dofs], problem.w[cols]
    scales = data_scales_from_arrays(problem.M_sym[dofs][:, dofs].tocsc(), H_c, f_c, w_c)
    data = {}  # MeasureData per arithmetic, built on first use
    local = np.searchsorted(cols, lp.keep[rows])
    scale = lp.scale[rows]
    HT64 = H_c.T.tocsr()

    def judge(v, r_t):
        # Judge what would be returned: the iterate rounded to float64, u = Hᵀv + w in float64.
        # (A longdouble iterate of a hyperstatic lattice met 1e-10 with r ~ 600·‖f‖ of
        # self-stress; rounded, its Hr lost 1e-9 of f.)  The arithmetic is the iterate's: float64
        # in the run's float64 phase (Settings.longdouble_below), where the criterion is far above
        # the rounding of either; solve() judges the returned answer in longdouble regardless.
        dtype = np.dtype(np.longdouble if np.asarray(v).dtype == np.longdouble else np.float64)
        if dtype not in data:
            data[dtype] = MeasureData(M_c, H_c, f_c, w_c, problem.mu[contacts], problem.mu_r[contacts], scales,
                                      Arithmetic(dtype))
        v64 = np.asarray(v, dtype=np.float64)
        r = np.zeros(cols.size)
        r[local] = scale * np.asarray(r_t, dtype=np.float64)
        out = data[dtype].measures(v64, HT64 @ v64 + w_c, r)
        return out if judge.share == 1.0 else dataclasses.replace(out, complementarity=out.complementarity * judge.share)

    judge.energy = scales.energy
    judge.share = float(share)
    return judge


def complementarity_share(problem: Problem, judges) -> float:
    """ΣE_c / E (at least 1) for the components' judges: E_c each one's energy scale, E the whole
    problem's.  E ≤ ΣE_c (fᵀM⁻¹f adds over the components; ‖w‖²/max W̃_kk is at most the
    largest component's), so a component held to |r_cᵀu_c| ≤ tol·E_c/share gives
    Σ|r_cᵀu_c| ≤ tol·E."""
    if len(judges) < 2:
        return 1.0
    whole = data_scales(problem).energy
    total = float(sum(j.energy for j in judges))
    return max(1.0, total / whole) if whole > 0 and math.isfinite(total) else 1.0
