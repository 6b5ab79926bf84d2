"""The 10-digit path at 10³–10⁴ contacts (issue 27 item 4): where its time and memory go.

Each (problem, engine) runs ``solve_to_digits(problem, digits=10, factor_engine=ENGINE)`` in a
child process of its own, so that its peak resident memory (``ru_maxrss`` of the child) is
the path's alone.  One row per run:

    contacts, dofs, engine, stage times (double, setup, extended, wide, proof, total), the path's
    total over its own double solve (/dbl: tol 1e-10, the paper's centring rule, as timed inside
    the path, where the set-up of the double-double phase runs beside it on two CPUs), over a
    plain ``rfverify.solve(problem)`` (plain, /pln: what ``rfverify solve FILE`` runs: tol 1e-10,
    the default centring rule) and over the path's own double solve with nothing beside it
    (alone, /aln) — each yardstick in a fresh child of its own, as the path was,
    extended iterations, the contact-space matrix (order, nnz of its upper triangle, nnz(L),
    Σ c_j² of L in the engine's order), factorisations, solves, refinement steps, the update
    (assembly + factorisation) seconds, peak memory (MB and kB per contact), proven digits.

Not a test: timings on a shared machine are noisy; compare rows of one run.

    python benchmarks/bench_digits_scale.py                               # random 300/1000 and 1000/3000
    python benchmarks/bench_digits_scale.py --problems scene:GranularBed:343 scene:GranularBed:1000 \
        scene:GranularBed:3375 --engines cholmod                          # 931, 2800, 9675 contacts
    python benchmarks/bench_digits_scale.py --problems random:3000:10000 --engines cholmod
    python benchmarks/bench_digits_scale.py --problems PILE.hdf5 --engines cholmod ldl
    python benchmarks/bench_digits_scale.py --problems scene:GranularBed:3375 --engines default  # no extra
    python benchmarks/bench_digits_scale.py --problems scene:GranularBed:3375:orientation=1 \
        scene:GranularBed:3375:orientation=1,gap_jitter=0,agitation=0 --engines default  # generic frames

A problem is ``random:NB:NC`` (``random_problem(NB, NC, seed=5)``: random rigid bodies, more
fill than granular media have), ``scene:NAME:SIZE[:KEY=VALUE,...]`` (``rfverify generate NAME --size SIZE --param KEY=VALUE``,
seed 0, its first problem: ``scene:GranularBed:3375`` is the 9675-contact bed, built in
seconds; ``:orientation=1`` turns it: generic contact frames) or an FCLIB file.
Set ``OPENBLAS_NUM_THREADS=1`` on a shared machine.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _results import recording  # noqa: E402  (stamped results file)


def load(spec: str):
    import rfverify
    from rfverify.scenes.random_problems import random_problem

    if spec.startswith("random:"):
        nb, nc = (int(x) for x in spec.split(":")[1:3])
        return random_problem(nb, nc, seed=5)
    if spec.startswith("scene:"):
        from rfverify.scenes import generate

        _, name, size, *params = spec.split(":")  # scene:NAME:SIZE[:KEY=VALUE,...]
        kw = {k: float(v) for k, v in (kv.split("=") for kv in ",".join(params).split(",") if kv)}
        return generate(name, count=1, seed=0, size=int(size), **kw)[0]
    return rfverify.load(spec)


ENGINES = ("cholmod", "ldl", "default", "noncholmod")
"""``factor_engine`` of the double-double phase (the double solve's form is ``auto``'s either
way, schur by CHOLMOD on the filled problems), or ``default``: the default install (CHOLMOD
from cvxopt, with the engines chosen by size), or ``noncholmod``: cvxopt made unimportable in the
child, so that every factorisation, the double solve's included, is QDLDL's (a trimmed install)."""


def one(spec: str, engine: str) -> dict:
    """Run the path once in this process; the row as a dict."""
    if engine == "noncholmod":
        sys.modules["cvxopt"] = sys.modules["cvxopt.cholmod"] = None  # an import of it now fails
    import rfverify
    from rfverify.engines.factor import schur_engine_name

    problem = load(spec)
    t0 = time.perf_counter()
    out = rfverify.solve_to_digits(problem, digits=10,
                                   factor_engine="auto" if engine in ("default", "noncholmod") else engine)
    total = time.perf_counter() - t0
    rss_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # the path's peak
    q = out.certificate.quantities
    digits = {k: (None if x.digits is None else round(x.digits, 2)) for k, x in q.items() if x.mode != "information"}
    ext = out.extended
    return {"problem": spec, "contacts": problem.n_contacts, "dofs": problem.n_dofs, "engine": engine,
            "timings": {k: round(v, 2) for k, v in out.timings.items()}, "wall": round(total, 2),

            "ext_iterations": int(getattr(ext, "nit", 0) or 0),
            "update_seconds": round(getattr(ext, "factor_seconds", 0.0), 2),
            "stats": getattr(ext, "stats", {}), "wide": None if out.wide is None else int(out.wide.nit),
            "wide_note": out.certificate.extra.get("wide_tail", ""), "certified": bool(out.success),
            "digits": digits, "double_method": out.double.method, "schur_engine": schur_engine_name(),
            "peak_MB": round(rss_kb / 1024, 1),
            "peak_kB_per_contact": round(rss_kb / max(problem.n_contacts, 1), 1),
            "backend": out.certificate.extra.get("backend", ""), "factorisation": getattr(ext, "factorisation", "")}


def yardstick(spec: str, which: str) -> dict:
    """A double solve alone, in a fresh process as the path's row was (the same first-call
    costs): "plain" = ``rfverify.solve(problem)``, what ``rfverify solve FILE`` runs; "alone" =
    the path's own double solve (``digits.DOUBLE_SETTINGS``) with nothing beside it."""
    import rfverify
    from rfverify.verify.digits import DOUBLE_SETTINGS

    problem = load(spec)
    t0 = time.perf_counter()
    out = rfverify.solve(problem, **(DOUBLE_SETTINGS if which == "alone" else {}))
    return {"seconds": round(time.perf_counter() - t0, 2), "status": str(out.status)}


def _child(args: list, timeout: float) -> dict:
    run = subprocess.run([sys.executable, __file__, *args], capture_output=True, text=True, timeout=timeout)
    if run.returncode != 0:
        raise RuntimeError(run.stderr[-2000:])
    return json.loads(run.stdout.strip().splitlines()[-1])


def _main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--problems", nargs="*", default=["random:300:1000", "random:1000:3000"])
    ap.add_argument("--engines", nargs="*", default=["cholmod", "ldl"], choices=ENGINES,
                    help="cholmod or ldl: the double-double phase's float64 factor; default: the default "
                         "install's choice; noncholmod: cvxopt unimportable (QDLDL everywhere) "
                         "(default: cholmod ldl)")
    ap.add_argument("--one", nargs=2, metavar=("PROBLEM", "ENGINE"), help=argparse.SUPPRESS)
    ap.add_argument("--yardstick", nargs=2, metavar=("PROBLEM", "WHICH"), help=argparse.SUPPRESS)
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per run (default 3600)")
    args = ap.parse_args(argv)
    if args.one:
        print(json.dumps(one(*args.one)), flush=True)
        return 0
    if args.yardstick:
        print(json.dumps(yardstick(*args.yardstick)), flush=True)
        return 0
    head = (f"{'problem':<28} {'n':>6} {'m':>6} {'engine':>7} {'double':>7} {'ext':>7} {'mp':>6} {'total':>7} "
            f"{'/dbl':>5} {'plain':>6} {'/pln':>5} {'alone':>6} {'/aln':>5} {'it':>3} {'order':>7} {'nnz(L)':>10} {'Σc²':>8} {'solves':>6} {'steps':>6} {'update':>7} "
            f"{'MB':>7} {'kB/c':>6}  proven")
    print(head)
    print("-" * len(head), flush=True)
    ok = True
    for spec in args.problems:
        for engine in args.engines:
            try:
                r = _child(["--one", spec, engine], args.timeout)
                r["plain_double"] = _child(["--yardstick", spec, "plain"], args.timeout)["seconds"]
                r["alone_double"] = _child(["--yardstick", spec, "alone"], args.timeout)["seconds"]
            except subprocess.TimeoutExpired:
                print(f"{spec:<28} {engine:>7}  did not finish in {args.timeout:.0f} s", flush=True)
                ok = False
                continue
            except RuntimeError as exc:
                print(f"{spec:<28} {engine:>7}  failed:\n{exc}", flush=True)
                ok = False
                continue
            t, s = r["timings"], r["stats"]
            mp = "–" if r["wide"] is None else f"{t['wide']:.1f}"
            dig = "/".join(f"{k} {v}" for k, v in r["digits"].items())
            print(f"{r['problem'][-28:]:<28} {r['contacts']:>6} {r['dofs']:>6} {engine:>7} {t['double']:>7.1f} "
                  f"{t['setup'] + t['extended']:>7.1f} {mp:>6} {t['total']:>7.1f} {t['total'] / t['double']:>5.2f} "
                  f"{r['plain_double']:>6.1f} {t['total'] / r['plain_double']:>5.2f} "
                  f"{r['alone_double']:>6.1f} {t['total'] / r['alone_double']:>5.2f} {r['ext_iterations']:>3} "
                  f"{s.get('order', 0):>7} {s.get('nnz_L', 0):>10} {s.get('sum_c2', 0):>8.1e} "
                  f"{s.get('solves', 0):>6} {s.get('refinement_steps', 0):>6} {r['update_seconds']:>7.1f} "
                  f"{r['peak_MB']:>7.0f} {r['peak_kB_per_contact']:>6.1f}  "
                  f"{'yes' if r['certified'] else 'NO'} {dig}", flush=True)
            if r.get("double_method") == "schur":
                print(f"    double solve: schur factored by {r['schur_engine']}", flush=True)
            if r.get("factorisation"):
                print(f"    extended phase: {r['factorisation']}", flush=True)
            if not r["certified"]:
                print(f"    tail: {r['wide_note']}", flush=True)
            ok = ok and r["certified"]
    return 0 if ok else 1


def main(argv=None):
    """Run, printing the table and writing it to benchmarks/results/bench_digits_scale.md (stamped);
    a child run (--one) prints its JSON row only."""
    if "--one" in (sys.argv[1:] if argv is None else argv):
        return _main(argv)
    with recording("bench_digits_scale", argv):
        return _main(argv)


if __name__ == "__main__":
    sys.exit(main())
