"""``bench --problem coulomb`` (issue 51): its tasks, the methods it takes, and what one of its
records says (for the bench's output and the report).  The tasks themselves run in
:mod:`rfverify.bench.tasks` (kind ``coulomb``)."""

from __future__ import annotations

from ..errors import BenchInputError
from ..solver.result import ALGORITHM1_METHODS


def plan_coulomb(problems, methods, tols, *, digits, max_iter, as_stored, time_limit, load_options=None) -> list[dict]:
    """Coulomb tasks: rfverify's path per (problem, method), GFC3D_IPM per (problem, tol)."""
    tasks = []
    for e in problems:
        base = {"problem": e.key, "collection": e.collection, "path": e.path, "sha256": e.sha256,
                "max_iter": max_iter, "kind": "coulomb", "digits": int(digits)}
        if as_stored:
            base["as_stored"] = True
        if load_options:
            base["load"] = dict(load_options)
        if time_limit:
            base["time_limit"] = float(time_limit)
        for method in methods:
            if method == "siconos":
                tasks += [{**base, "method": method, "tol": float(tol)} for tol in tols]
            else:
                tasks.append({**base, "method": method})
    return tasks


COULOMB_DEFAULT_METHODS = ("auto",)
"""What ``bench --problem coulomb`` runs unless told otherwise: rfverify's Coulomb path with
the ``auto`` inner solver (add ``siconos`` for Siconos's GFC3D_IPM, certified beside it)."""


def check_coulomb_methods(methods) -> None:
    """``--problem coulomb`` takes the inner solvers of rfverify's path (auto and the
    Algorithm 1 methods) and ``siconos`` (its GFC3D_IPM); a BenchInputError names the others."""
    ok = ("auto",) + tuple(ALGORITHM1_METHODS) + ("siconos",)
    bad = [m for m in methods if m not in ok]
    if bad:
        raise BenchInputError(f"--methods {','.join(bad)}: not a method of --problem coulomb (it takes rfverify's "
                              f"inner solvers {', '.join(ok[:-1])} and siconos, Siconos's GFC3D_IPM); fix: pass "
                              f"e.g. --methods auto,siconos")


def coulomb_summary(problem: str, rec: dict, task: dict | None = None) -> dict:
    """What a Coulomb record says, for the bench's output and the report: who answered
    (``solver``: "rfverify (auto)" or "Siconos GFC3D_IPM"), ``certified``, the proven relative
    ``backward_error`` (None when none was proven), the proven ``digits`` per quantity, the
    iterations (``outer``: our convex solves + proven rounds, or GFC3D's iterations),
    ``time`` and ``why`` (the verdict or the failure, in words)."""
    task = task or rec
    method = task.get("method", rec.get("method"))
    peer = method == "siconos"
    tol = task.get("tol", rec.get("tol"))
    def plural(k, noun):
        return f"{k} {noun}{'' if k == 1 else 's'}"

    if peer:
        ran = isinstance(rec.get("peer_iterations"), int) and rec.get("peer_status") != "NotRun"
        outer = plural(rec["peer_iterations"], "IPM iteration") if ran else ""
    elif isinstance(rec.get("outer_evaluations"), int):
        outer = (f"{plural(rec['outer_evaluations'], 'convex solve')} + "
                 f"{plural(rec.get('proven_rounds', 0), 'proven round')}")
    else:
        outer = ""
    return {"problem": problem, "method": method, "tol": tol,
            "solver": f"Siconos GFC3D_IPM (tol {tol:g})" if peer else f"rfverify ({method})",
            "status": rec.get("status", "Missing"), "certified": rec.get("certified") is True,
            "backward_error": rec.get("backward_error"), "digits": rec.get("certified_digits") or {},
            "outer": outer, "peer_status": rec.get("peer_status"), "time": rec.get("time"),
            "why": " ".join(str(rec.get("message") or "no record").split())}
