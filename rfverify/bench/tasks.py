"""One benchmark task, run in its own process: solve, verify independently, save.

Task kinds
----------
``solve``       one method at one tolerance, timed; the final (v, u, r) is saved and rechecked
                in high precision (:mod:`rfverify.bench.verify`).
``trajectory``  one Algorithm 1 method at a tight tolerance with every iterate kept; each
                iterate (mapped back to the original variables) is rechecked, giving the
                verified error against elapsed time (work–precision data) and how far double
                precision gets.
``digits``      the mixed-precision path (:func:`rfverify.verify.digits.solve_to_digits`, timed in
                its parts) and its certificate; its proven extended-precision point is saved
                (every float64 term) and serves as the problem's reference: the report proves
                every other saved answer's digits at it (:mod:`rfverify.report.proven`).
``coulomb``     the physical problem (``bench --problem coulomb``, issue 51): method ``siconos``
                runs Siconos's GFC3D_IPM at ``tol`` on a 3-D problem and certifies its answer
                (:func:`rfverify.coulomb.certify_coulomb`); any other method is the inner solver
                of rfverify's own path (:func:`rfverify.coulomb.coulomb_to_digits`).  Both at
                ``digits``, both judged by the proven backward error and proven digits.

Each task writes ``<stem>.npz`` (arrays) then ``<stem>.json`` (record, declared in
:mod:`rfverify.bench.records`); the JSON is written last, atomically, so its presence means the
task finished (what resume relies on).
"""

from __future__ import annotations

import hashlib
import math
import time
import traceback
import warnings
from pathlib import Path

import numpy as np

from ..errors import BenchInputError
from ..io.output import dumps
from .records import FORMAT_VERSION, new_record, task_stem, tol_text, write_json
from .verify import HighPrecisionChecker

SOLVE_SHARE = 0.8
TRAJECTORY_SHARE = 0.5
"""Shares of a task's time limit its solver gets (the rest is for rechecking and writing): the
solver stops at its limit and the record keeps the best answer with status MaxTime, where the
bench would otherwise kill the task and keep nothing.  A trajectory rechecks every iterate in
30-digit arithmetic afterwards, hence its smaller share."""


def solver_time_limit(task: dict, share: float) -> dict:
    """``{"time_limit": share × the task's limit}`` for the solver, or {} without one."""
    limit = task.get("time_limit")
    return {} if not limit else {"time_limit": share * float(limit)}


def load_for_bench(path, options: dict | None):
    """The problem at ``path`` as a bench run loads it: ``options`` (the run's ``load``, from
    ``bench --max-asymmetry X --psd-shift``) may hold ``max_asymmetry`` (the limit of the
    loader's refusal; default its own) and ``psd_shift`` (True: a local W that is not PSD as
    stored is proven as W + D, :func:`rfverify.shift_to_psd`; a global problem, which has no W,
    is left as it is, so that one run may hold both)."""
    from ..io import load
    from ..model.problem import DEFAULT_MAX_ASYMMETRY

    options = options or {}
    limit = options.get("max_asymmetry")
    problem = load(path, max_asymmetry=DEFAULT_MAX_ASYMMETRY if limit is None else float(limit))
    if options.get("psd_shift") and problem.local is not None:
        from ..proof.psd_shift import shift_to_psd

        problem = shift_to_psd(problem)
    return problem


def check_one_choice(run_dir, old: dict, as_stored: bool, load_options: dict | None) -> dict:
    """The run's load options without their defaults; a BenchInputError where the run directory's
    manifest ``old`` was made with another choice of ``--as-stored`` or of the load options (one
    run directory, one way of posing its problems)."""
    if old and bool(old.get("as_stored", False)) != bool(as_stored):
        raise BenchInputError(f"{run_dir}: its runs were made {'with' if old.get('as_stored') else 'without'} "
                              f"--as-stored; fix: give another --out for runs "
                              f"{'with' if as_stored else 'without'} it")
    load_options = {k: v for k, v in (load_options or {}).items() if v not in (None, False)}
    if old and (old.get("load_options") or {}) != load_options:
        raise BenchInputError(f"{run_dir}: its problems were loaded with {old.get('load_options') or 'the defaults'}, "
                              f"not {load_options or 'the defaults'} (--max-asymmetry, --psd-shift); fix: give "
                              "another --out for runs loaded otherwise")
    return load_options


def task_key(task: dict) -> str:
    """Hash of everything that determines a task's result: the problem file's content, the
    kind, method, tolerance, iteration limit, recheck precision, digits, every solver setting
    (defaults included: a changed default re-runs the task), rfverify's version and the
    record schema; for the Siconos peer also its build (:func:`rfverify.solver.siconos_peer.build_id`)."""
    from .. import __version__
    from ..solver import Settings

    settings = {}
    for name in Settings.names():
        value = getattr(Settings(), name)
        settings[name] = value if isinstance(value, (bool, int, float, str, type(None))) else repr(value)
    what = {"schema": FORMAT_VERSION, "rfverify": __version__, "sha256": task["sha256"],
            "kind": task["kind"], "method": task.get("method"),
            "tol": None if task.get("tol") is None else tol_text(task["tol"]),
            "max_iter": task.get("max_iter"), "dps": task.get("dps"), "digits": task.get("digits"),
            "settings": settings}
    if task.get("as_stored"):  # only then: the keys of default runs are unchanged
        what["as_stored"] = True
    if task.get("load"):  # likewise: a problem loaded otherwise (--max-asymmetry, --psd-shift) is another task
        what["load"] = task["load"]
    if task.get("method") == "siconos":  # a rebuilt peer (other sources, patches, driver) re-runs its tasks
        from ..solver.siconos_peer import build_id

        what["siconos_build"] = build_id()
    return hashlib.sha256(dumps(what, sort_keys=True).encode()).hexdigest()


def task_label(task: dict) -> str:
    if task["kind"] == "digits":
        return f"{task['problem']} · {task['digits']}-digit path"
    if task["kind"] == "coulomb":
        who = f"Siconos GFC3D_IPM {task['tol']:g}" if task["method"] == "siconos" else f"rfverify ({task['method']})"
        return f"{task['problem']} · coulomb, {who}, {task['digits']} digits"
    kind = "" if task["kind"] == "solve" else f"{task['kind']} "
    return f"{task['problem']} · {kind}{task['method']} {task['tol']:g}"


def base_record(task: dict) -> dict:
    """The fields every record of ``task`` carries (:func:`rfverify.bench.records.new_record`)."""
    return new_record(task, task_key(task))


def run_task(task: dict, out_dir: str) -> None:
    """Entry point of the child process: run ``task``, write its record (also on failure)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    stem = task_stem(task)
    record = base_record(task)
    with warnings.catch_warnings(record=True) as caught:
        # A worker's stderr is the bench's: warnings go into the record instead.
        warnings.simplefilter("always")
        try:
            problem = load_for_bench(task["path"], task.get("load"))
            if task.get("as_stored"):  # the stored, unsymmetric M: solved, rechecked and proven as such
                problem = problem.stored_equations()
            record.update(n_contacts=problem.n_contacts, n_dofs=problem.n_dofs, problem_statement=problem.statement)
            if task["kind"] == "solve":
                record.update(_solve(problem, task, out / f"{stem}.npz"))
            elif task["kind"] == "trajectory":
                record.update(_trajectory(problem, task, out / f"{stem}.npz"))
            elif task["kind"] == "coulomb":
                record.update(_coulomb(problem, task, out / f"{stem}.npz"))
            else:
                record.update(_digits(problem, task, out / f"{stem}.npz"))
        except Exception as exc:  # a crash is a result too: recorded with its cause
            record.update(status="Error", solved=False,
                          message=f"{type(exc).__name__}: {' '.join(str(exc).split())}",
                          traceback=traceback.format_exc(limit=8))
    if caught:
        counts = {}
        for w in caught:
            key = f"{w.category.__name__}: {' '.join(str(w.message).split())}"
            counts[key] = counts.get(key, 0) + 1
        record["numerical_warnings"] = [f"{k} (×{n})" if n > 1 else k for k, n in counts.items()]
    write_json(out / f"{stem}.json", record)


def _solve(problem, task, npz_path) -> dict:
    from ..solver import kernels, solve

    # The timed solve is the solve: numba's once-per-process start-up of the compiled cone
    # kernels (~0.3 s; nothing after a fork from the warmed runner) is not part of it, as
    # Clarabel's library load is not part of Clarabel's.
    kernels.warm_up()
    t0 = time.perf_counter()
    res = solve(problem, method=task["method"], tol=task["tol"], max_iter=task.get("max_iter", 100),
                **solver_time_limit(task, SOLVE_SHARE))
    elapsed = time.perf_counter() - t0
    trace = {k: np.asarray(v, dtype=np.float64) for k, v in res.trace.items()}
    np.savez_compressed(npz_path, v=res.v, u=res.u, r=res.r, **{f"trace_{k}": v for k, v in trace.items()})
    verified = HighPrecisionChecker(problem, task.get("dps", 30)).criterion(res.v, res.u, res.r)
    own, claim, claim_tol = solver_claim(res, task["tol"])
    return {
        "status": str(res.status), "message": res.message, "nit": int(res.nit), "time": elapsed,
        "solver_status_own": own, "claim": claim, "claim_tol": claim_tol,
        "solver_claims_solved": claim == "Solved",
        "refuted": bool(claim is not None and not verified["max"] <= claim_tol),
        "solver_measures": {"criterion": res.criterion, "pinfeas": res.pinfeas, "dinfeas": res.dinfeas,
                            "mu": res.mu},
        "verified": verified, "solved": bool(verified["max"] <= task["tol"]),
        **_extremes_over_components(res),
        "presolve": res.presolve,
    }


def solver_claim(res, tol: float):
    """What the solver itself claims, in its own words: (own status verbatim, claim, the
    tolerance the claim asserts).  Algorithm 1 claims Solved at ``tol`` and AlmostSolved at
    ``almost_factor·tol``; Clarabel claims its own status, AlmostSolved meaning its reduced
    tolerances (kept in ``extras["clarabel_almost_tol"]``); Siconos claims Solved when its info is 0
    (``extras["siconos_status"]``).  A claim is refuted when the
    independent recheck's criterion exceeds the claimed tolerance."""
    own = str(res.extras.get("clarabel_status", res.extras.get("siconos_status", res.status)))
    if own == "Solved":
        return own, "Solved", float(tol)
    if own == "AlmostSolved":
        almost = res.extras.get("clarabel_almost_tol", res.settings.almost_factor * tol)
        return own, "AlmostSolved", float(almost)
    return own, None, None


def _nan_extreme(values, reducer) -> float | None:
    """``reducer`` (np.nanmax/np.nanmin) of a trace column, None when it holds no number
    (Clarabel has no trace; forms without Q_p record NaN)."""
    if values is None:
        return None
    values = np.asarray(values, dtype=np.float64)
    values = values[~np.isnan(values)]
    return float(reducer(values)) if values.size else None


def _extremes_over_components(res) -> dict:
    """``max_cond_Qp`` and ``min_lam2`` over every independent component's trace (``res.trace``
    is the longest component's only: a split run's worst cond(Q_p) may be in another)."""
    traces = [run["trace"] for run in res.extras.get("component_runs") or []] or [res.trace]
    conds = [x for x in (_nan_extreme(t.get("max_cond_Qp"), np.nanmax) for t in traces) if x is not None]
    lams = [x for x in (_min_lam2(t) for t in traces) if x is not None]
    return {"max_cond_Qp": max(conds) if conds else None, "min_lam2": min(lams) if lams else None}


def _min_lam2(trace) -> float | None:
    vals = [x for x in (_nan_extreme(trace.get(k), np.nanmin) for k in ("min_lam2_z", "min_lam2_s")) if x is not None]
    return min(vals) if vals else None


def _trajectory(problem, task, npz_path) -> dict:
    from ..model.lifting import lift
    from ..solver import kernels, solve

    kernels.warm_up()  # as in _solve
    t0 = time.perf_counter()
    res = solve(problem, method=task["method"], tol=task["tol"], max_iter=task.get("max_iter", 100),
                keep_iterates=True, **solver_time_limit(task, TRAJECTORY_SHARE))
    elapsed = time.perf_counter() - t0
    lp = lift(problem, reduce_cones=res.settings.reduce_cones)
    active = res.extras["active_dofs"]
    checker = HighPrecisionChecker(problem, task.get("dps", 30))
    times = np.asarray(res.trace["time"], dtype=np.float64)
    vs, rs, crit = [], [], []
    for k, (v_k, r_t_k, _z) in enumerate(res.extras["iterates"]):
        v = np.array(res.v, dtype=np.float64)
        v[active] = np.asarray(v_k, dtype=np.float64)
        r = lp.r_from_lifted(np.asarray(r_t_k, dtype=np.float64))
        u = lp.u_from_v(v)
        vs.append(v)
        rs.append(r)
        crit.append(checker.criterion(v, u, r))
    n_it = min(len(vs), times.size)
    np.savez_compressed(npz_path, v=np.array(vs[:n_it]), r=np.array(rs[:n_it]), time=times[:n_it])
    return {
        "status": str(res.status), "message": res.message, "nit": int(res.nit), "time": elapsed,
        "iterates": [{"time": float(times[k]), "verified_max": crit[k]["max"],
                      "mu": float(res.trace["mu"][k]),
                      "max_cond_Qp": _finite(res.trace["max_cond_Qp"][k]),
                      "min_lam2_z": _finite(res.trace["min_lam2_z"][k]),
                      "min_lam2_s": _finite(res.trace["min_lam2_s"][k])}
                     for k in range(n_it)],
        "best_verified_max": float(min((c["max"] for c in crit), default=math.inf)),
        "solved": False,  # a trajectory is data for curves, not a counted run
    }


def _finite(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _digits(problem, task, npz_path) -> dict:
    from ..verify.digits import solve_to_digits

    digits = int(task["digits"])
    t0 = time.perf_counter()
    out = solve_to_digits(problem, digits=digits, **solver_time_limit(task, SOLVE_SHARE))
    elapsed = time.perf_counter() - t0
    cert = out.certificate
    arrays = {"v": out.v, "u": out.u, "r": out.r}
    if out.point is not None and cert.proof is not None and cert.proof.valid:
        # The proven extended point is the reference that grades every other saved solution.
        arrays.update(ref_v=out.point.v_hi, ref_r=out.point.r_hi, ref_u=out.u,
                      point_v_lo=out.point.v_lo, point_r_lo=out.point.r_lo)
        if out.point.v_more is not None:  # a multiple-precision point: every term, for the report's proofs
            arrays.update(point_v_more=out.point.v_more, point_r_more=out.point.r_more)
    np.savez_compressed(npz_path, **arrays)
    verified = HighPrecisionChecker(problem, 40).criterion(out.v, out.u, out.r)
    t = out.timings
    return {
        "status": str(out.status), "message": cert.verdict,
        "time": elapsed, "time_double": t["double"], "time_warm": t["setup"] + t["extended"] + t["wide"],
        "time_certify": t["proof"],
        "double_status": str(out.double.status), "warm_iterations": int(out.extended.nit),
        "wide_iterations": 0 if out.wide is None else int(out.wide.nit),
        "certified": bool(cert.certified), "certified_digits": cert.digits,
        # relative, absolute (x* ≈ 0: judged against a data scale, DESIGN §6.3) or information
        "certified_modes": {k: q.mode for k, q in cert.quantities.items()},
        "r_unique": cert.r_unique, "has_reference": "ref_v" in arrays,
        "reference_status": "proven extended point" if "ref_v" in arrays else None,
        "verified": verified, "solved": bool(cert.certified),
    }


def _coulomb_fields(cert, problem, v, u, r, shift) -> dict:
    """The record fields of a Coulomb certificate (:class:`rfverify.coulomb.CoulombCertificate`)
    of the answer (v, u, r), with the physical conditions it meets (long double, relative to the
    data scale of u, :func:`rfverify.coulomb.physical_residuals`)."""
    from ..coulomb import physical_residuals

    be = cert.backward
    res = physical_residuals(problem, u, r, shift)
    return {"certified": bool(cert.certified), "solved": bool(cert.certified),
            "backward_error": be.relative if be.proven and math.isfinite(be.relative) else None,
            "backward_proven": bool(be.proven),
            "certified_digits": cert.digits, "certified_modes": {k: q.mode for k, q in cert.quantities.items()},
            "certificate_status": str(cert.status), "verdict": cert.verdict,
            "physical_residuals": res.as_dict()}


def _coulomb(problem, task, npz_path) -> dict:
    """One Coulomb task: rfverify's path, or Siconos's GFC3D_IPM certified (module docstring)."""
    from ..coulomb import certify_coulomb, coulomb_to_digits

    digits = int(task["digits"])
    if task["method"] == "siconos":
        return _coulomb_peer(problem, task, npz_path, digits)
    t0 = time.perf_counter()
    out = coulomb_to_digits(problem, digits=digits, method=task["method"], max_iter=task.get("max_iter", 100),
                            **solver_time_limit(task, SOLVE_SHARE))
    elapsed = time.perf_counter() - t0
    np.savez_compressed(npz_path, v=out.v, u=out.u, r=out.r, shift=out.shift)
    run = out.outer
    return {"status": str(out.status), "message": out.certificate.verdict, "time": elapsed, "nit": int(out.nit),
            **_coulomb_fields(out.certificate, problem, out.v, out.u, out.r, out.shift),
            "outer_method": run.method, "outer_evaluations": int(run.total_evaluations),
            "outer_residual": float(run.residual), "proven_rounds": len(out.rounds),
            "time_outer": out.timings.get("outer"), "time_proven": out.timings.get("proven")}


def _coulomb_peer(problem, task, npz_path, digits: int) -> dict:
    """Siconos's GFC3D_IPM on the problem at ``tol``, then the backward-error certificate of its
    (v, r) with u = Hᵀv + w and ŝ = Φ(u): what its answer is proven to be, whatever it claims."""
    from ..coulomb import certify_coulomb
    from ..solver.siconos_peer import solve_gfc3d

    limit = task.get("time_limit")
    t0 = time.perf_counter()
    ans = solve_gfc3d(problem, tol=float(task["tol"]), max_iter=task.get("max_iter", 100),
                      time_limit=None if not limit else 0.4 * float(limit))
    t_peer = time.perf_counter() - t0
    peer = {"peer_status": ans.status, "peer_info": ans.info, "peer_iterations": int(ans.nit),
            "peer_residual": ans.residual, "peer_seconds": ans.seconds, "time_peer": t_peer}
    if not ans.answered:
        np.savez_compressed(npz_path, v=ans.v, r=ans.r)
        status = "NotRun" if ans.status == "NotRun" else ("MaxTime" if ans.status == "MaxTime" else "PeerFailed")
        return {"status": status, "message": ans.failure, "time": t_peer, "certified": False, "solved": False,
                "backward_error": None, "nit": 0, **peer}
    left = None if not limit else max(SOLVE_SHARE * float(limit) - t_peer, 1.0)
    t1 = time.perf_counter()
    cert = certify_coulomb(problem, ans.v, None, ans.r, digits=digits, time_limit=left)
    t_cert = time.perf_counter() - t1
    u = problem.H.T @ ans.v + np.asarray(problem.w)
    np.savez_compressed(npz_path, v=ans.v, u=u, r=ans.r, u_siconos=ans.u_siconos, shift=cert.shift)
    return {"status": str(cert.status), "message": cert.verdict, "time": t_peer + t_cert, "nit": int(ans.nit),
            **_coulomb_fields(cert, problem, ans.v, u, ans.r, cert.shift), **peer, "time_certify": t_cert}
