"""The cost of solving the stored, unsymmetric equations (``--as-stored``) against the default
(M + Mᵀ)/2, on the real files with an unsymmetric M and on generated problems with a planted
skew part (issue 37).

Per problem and mode: the double solve (time, status) and the 10-digit path (time, verdict,
fewest proven digits), medians of ``--repeat`` runs in one process, and the dynamics residual of
each answer against the *stored* M (what ``--as-stored`` promises to make small).  Not a test:
compare the ratios measured within one run.

    python benchmarks/bench_as_stored.py
    python benchmarks/bench_as_stored.py --sizes 100,1000 --repeat 3
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

import rfverify
from rfverify.scenes.random_problems import random_problem

sys.path.insert(0, str(Path(__file__).parent))
from _results import recorded  # noqa: E402  (stamped results file)


def with_skew(problem, asymmetry: float, seed: int):
    """``problem`` with M + A, A skew on M's diagonal blocks, |A_ij| ≤ asymmetry·√(M_ii M_jj)/2
    (entrywise asymmetry about ``asymmetry``, as the Chute's 2.0e-3)."""
    rng = np.random.default_rng(seed)
    M = sp.coo_matrix(problem.M)
    keep = M.row < M.col
    d = problem.M.diagonal()
    vals = asymmetry * 0.5 * np.sqrt(d[M.row[keep]] * d[M.col[keep]]) * rng.uniform(-1, 1, keep.sum())
    A = sp.coo_matrix((vals, (M.row[keep], M.col[keep])), shape=M.shape)
    return rfverify.Problem.from_arrays((problem.M + A - A.T).tocsc(), problem.H, problem.f, problem.w, problem.mu,
                                        problem.mu_r, title=f"{problem.title} + skew {asymmetry:g}")


def problems(sizes):
    for name in ("chute", "chute-dat"):
        yield f"bundled:{name}", rfverify.load(f"bundled:{name}")
    for n in sizes:
        base = random_problem(max(2, int(0.6 * n)), n, seed=n)
        yield f"random-n{n} + skew 2e-3", with_skew(base, 2e-3, seed=n)


def stored_residual(problem, v, r) -> float:
    """‖M v − H r − f‖∞ / max(‖Mv‖∞, ‖f‖∞) with the stored M."""
    Mv = problem.M @ v
    return float(np.max(np.abs(Mv - problem.H @ r - problem.f)) / max(np.max(np.abs(Mv)), np.max(np.abs(problem.f))))


def timed(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


@recorded("bench_as_stored")
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="100,1000", help="contact counts of generated problems")
    ap.add_argument("--repeat", type=int, default=3, help="timed repetitions (median kept)")
    ap.add_argument("--digits", type=int, default=10)
    args = ap.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",") if s]
    rfverify.solve_to_digits(rfverify.load("bundled:chute"), digits=args.digits)  # compile the kernels first
    print("| problem | n | entrywise asymmetry | mode | double solve s | status | stored residual | "
          f"{args.digits}-digit path s | verdict | fewest proven digits | stored residual |")
    print("|---|---:|---:|---|---:|---|---:|---:|---|---:|---:|")
    ratios = []
    for name, p in problems(sizes):
        row = {}
        for mode, as_stored in (("(M + Mᵀ)/2", False), ("as stored", True)):
            t_s, res = timed(lambda: rfverify.solve(p, as_stored=as_stored), args.repeat)
            t_d, out = timed(lambda: rfverify.solve_to_digits(p, digits=args.digits, as_stored=as_stored), args.repeat)
            fewest = out.certificate.proof.fewest_digits() if out.certificate.proof is not None else None
            row[mode] = (t_s, t_d)
            print(f"| {name} | {p.n_contacts} | {p.symmetry.scaled:.1e} | {mode} | {t_s:.2f} | {res.status} | "
                  f"{stored_residual(p, res.v, res.r):.1e} | {t_d:.2f} | {out.status} | "
                  f"{'—' if fewest is None else f'{fewest:.1f}'} | {stored_residual(p, out.v, out.r):.1e} |")
        (s0, d0), (s1, d1) = row["(M + Mᵀ)/2"], row["as stored"]
        ratios.append((name, s1 / s0, d1 / d0))
    print()
    print("time as stored / time with (M + Mᵀ)/2 (same run):")
    for name, rs, rd in ratios:
        print(f"- {name}: double solve {rs:.2f}×, {args.digits}-digit path {rd:.2f}×")


if __name__ == "__main__":
    main()
