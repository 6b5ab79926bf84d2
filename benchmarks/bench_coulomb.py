"""The physical problem (issue 51) on every file family: how the outer iteration on De Saxcé's
shift converges (Picard against Anderson, over double solves), and the proven path
(``solve --problem coulomb --digits K``): proven rounds, backward error, time, and an independent
recheck of its answer against the physical conditions in long double (written here, not
rfverify's measures).

    PYTHONPATH=. python benchmarks/bench_coulomb.py FILE_OR_DIR... [--digits 10] [--three-d]

``--three-d`` also runs each rolling file's 3-D version (rolling rows dropped, μr = 0: the
problem a 3-D FCLIB /fclib_global file of the same scene poses).  ``--write-3d DIR`` only writes
those 3-D versions as FCLIB ``/fclib_global`` files (spacedim 3) into DIR, e.g. for
``rfverify bench DIR --problem coulomb --methods auto,siconos`` (Siconos's GFC3D_IPM is 3-D only).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _results import recording  # noqa: E402

import rfverify  # noqa: E402
from rfverify.coulomb import coulomb_to_digits, solve_coulomb  # noqa: E402
from rfverify.coulomb.outer import CONTINUE_ABOVE  # noqa: E402


def recheck(problem, v, r, detail: bool = False):
    """The largest relative violation of the physical conditions at (v, r), in long double:
    dynamics ((M+Mᵀ)/2 v − H r − f against |M||v| + |H||r| + |f|), u_N ≥ 0 (against the terms
    of u, ‖|Hᵀ||v| + |w|‖∞ or ‖|W||r| + |q|‖∞, and ‖HᵀM⁻¹f + w‖∞ or ‖q‖∞), the friction cones (against ‖r‖∞) and
    max_i |r_iᵀũ_i| (against ‖r‖∞ times the larger of ‖ũ‖∞ and u's terms); ‖r‖∞ is at least
    ‖f‖∞ / max_k ‖h_k‖₂ (‖q‖∞ / max W_kk for a local file).  ``detail``: each of the four."""
    ld = np.longdouble
    v, r = np.asarray(v, dtype=ld), np.asarray(r, dtype=ld)
    M = problem.M.tocoo()
    Md, Mr, Mc = M.data.astype(ld) / 2, M.row, M.col
    Mv = np.zeros(problem.n_dofs, dtype=ld)
    np.add.at(Mv, Mr, Md * v[Mc])
    np.add.at(Mv, Mc, Md * v[Mr])
    Mabs = np.zeros(problem.n_dofs, dtype=ld)
    np.add.at(Mabs, Mr, np.abs(Md * v[Mc]))
    np.add.at(Mabs, Mc, np.abs(Md * v[Mr]))
    H = problem.H.tocoo()
    Hd = H.data.astype(ld)
    Hr = np.zeros(problem.n_dofs, dtype=ld)
    np.add.at(Hr, H.row, Hd * r[H.col])
    Habs = np.zeros(problem.n_dofs, dtype=ld)
    np.add.at(Habs, H.row, np.abs(Hd * r[H.col]))
    u = np.asarray(problem.w, dtype=ld).copy()
    np.add.at(u, H.col, Hd * v[H.row])
    u_terms = np.abs(np.asarray(problem.w, dtype=ld)).copy()  # |Hᵀ||v| + |w|: what u is made of
    np.add.at(u_terms, H.col, np.abs(Hd * v[H.row]))
    if problem.local is not None:  # the file's own u = (W + Wᵀ)/2 r + q; no dynamics
        W = problem.local.W.tocoo()
        u = np.asarray(problem.local.q, dtype=ld).copy()
        u_terms = np.abs(u).copy()
        np.add.at(u, W.row, W.data.astype(ld) / 2 * r[W.col])
        np.add.at(u, W.col, W.data.astype(ld) / 2 * r[W.row])
        np.add.at(u_terms, W.row, np.abs(W.data.astype(ld) / 2 * r[W.col]))
        np.add.at(u_terms, W.col, np.abs(W.data.astype(ld) / 2 * r[W.row]))
        dyn = ld(0)
    else:
        f = np.asarray(problem.f, dtype=ld)
        scale = np.max(Mabs) + np.max(Habs) + np.max(np.abs(f))
        dyn = np.max(np.abs(Mv - Hr - f)) / scale if scale > 0 else ld(0)
    U, R = u.reshape(-1, 5), r.reshape(-1, 5)
    mu, mur = np.asarray(problem.mu, dtype=ld), np.asarray(problem.mu_r, dtype=ld)
    phi = mu * np.sqrt(U[:, 1] ** 2 + U[:, 2] ** 2) + mur * np.sqrt(U[:, 3] ** 2 + U[:, 4] ** 2)
    T = U.copy()
    T[:, 0] += phi
    # u against its terms and the data's own velocity ‖HᵀM⁻¹f + w‖∞ (‖q‖∞), not ‖u‖∞: u = 0
    # where every contact sticks
    if problem.local is not None:
        u_data = np.max(np.abs(np.asarray(problem.local.q, dtype=ld)))
    else:
        from scipy.sparse.linalg import spsolve

        free = spsolve(sp.csc_matrix((problem.M + problem.M.T) / 2), np.asarray(problem.f, dtype=np.float64))
        u_data = np.max(np.abs(problem.H.T @ free + problem.w))
    u_inf = max(np.max(u_terms), u_data) or ld(1)
    # r against the reactions the data can ask for, ‖f‖∞ (‖q‖∞) over the largest column of H
    # (diagonal of W), not ‖r‖∞: r = 0 where every contact is open
    if problem.local is not None:
        r_data = np.max(np.abs(np.asarray(problem.local.q, dtype=ld))) / np.max(problem.local.W.diagonal())
    else:
        col = np.sqrt(np.asarray(problem.H.multiply(problem.H).sum(axis=0), dtype=ld).ravel())
        r_data = np.max(np.abs(np.asarray(problem.f, dtype=ld))) / np.max(col)
    r_inf = max(np.max(np.abs(R)), r_data) or ld(1)
    t_inf = max(np.max(np.abs(T)), u_inf)
    normal = max(ld(0), -np.min(U[:, 0])) / u_inf
    cone = max(ld(0), np.max(np.maximum(np.sqrt(R[:, 1] ** 2 + R[:, 2] ** 2) - mu * R[:, 0],
                                        np.sqrt(R[:, 3] ** 2 + R[:, 4] ** 2) - mur * R[:, 0]))) / r_inf
    comp = np.max(np.abs(np.sum(T * R, axis=1))) / (r_inf * t_inf)
    parts = {"dynamics": dyn, "normal": normal, "cone": cone, "complementarity": comp}
    return {k: float(x) for k, x in parts.items()} if detail else float(max(parts.values()))


def three_d(problem):
    """The 3-D problem of a rolling one: rolling columns of H and rows of w zero, μr = 0."""
    n = problem.n_contacts
    keep = np.ones(5 * n)
    keep[3::5] = keep[4::5] = 0
    H = sp.csc_matrix(problem.H @ sp.diags(keep))
    return rfverify.Problem.from_arrays(problem.M, H, problem.f, np.asarray(problem.w) * keep, problem.mu,
                                        np.zeros(n), title=problem.title + " (3-D)", max_asymmetry=np.inf,
                                        provenance={"format": "fclib_global", "spacedim": 3})


def files(inputs):
    for spec in inputs:
        p = Path(spec)
        if p.is_dir():
            yield from sorted(x for x in p.rglob("*") if x.suffix in (".hdf5", ".h5", ".dat"))
        else:
            yield spec


def row(name, problem, digits):
    n = problem.n_contacts
    cells = [name, str(n)]
    for outer in ("picard", "anderson"):
        t0 = time.perf_counter()
        out = solve_coulomb(problem, outer=outer, outer_tol=1e-13, continuation=False)
        cells.append(f"{out.outer.evaluations} ({out.outer.residual:.0e}, {time.perf_counter() - t0:.1f} s)")
        if outer == "anderson" and out.outer.residual > CONTINUE_ABOVE:  # the default continues in friction
            t0 = time.perf_counter()
            out = solve_coulomb(problem, outer=outer, outer_tol=1e-13)
            cells.append(f"{out.outer.total_evaluations} ({out.outer.residual:.0e}, {time.perf_counter() - t0:.1f} s, "
                         f"{len(out.outer.stages) - 1} stages)")
        elif outer == "anderson":
            cells.append("–")
    t0 = time.perf_counter()
    out = coulomb_to_digits(problem, digits=digits)
    wall = time.perf_counter() - t0
    cells += [str(len(out.rounds)), f"{out.backward_error:.1e}", str(out.status),
              " ".join(f"{k} {d:.1f}" if d is not None else f"{k} -" for k, d in out.digits.items()),
              f"{recheck(problem, out.v, out.r):.1e}", f"{wall:.1f}"]
    return "| " + " | ".join(cells) + " |"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("inputs", nargs="+")
    ap.add_argument("--digits", type=int, default=10)
    ap.add_argument("--three-d", action="store_true")
    ap.add_argument("--write-3d", metavar="DIR")
    args = ap.parse_args(argv)
    if args.write_3d:
        out = Path(args.write_3d)
        out.mkdir(parents=True, exist_ok=True)
        for spec in files(args.inputs):
            problem = rfverify.load(str(spec))
            if problem.local is None and np.any(problem.mu_r > 0):
                name = Path(str(spec).replace("bundled:", "bundled-")).stem
                rfverify.save(three_d(problem), out / f"{name}-3d.hdf5")
                print(out / f"{name}-3d.hdf5")
        return
    with recording("bench_coulomb", argv):
        print(f"Physical problem (--problem coulomb), --digits {args.digits}. Outer columns: convex solves to a "
              "fixed-point residual of 1e-13 of the data scale of u (best residual, time), Picard and Anderson alone, then the "
              "default (Anderson, and the friction continuation where it stops above 1e-8); the proven path is the default's; proven rounds: "
              "the k-digit path run again from Φ of each proven answer; recheck: the largest relative violation of "
              "the physical conditions in long double, independent of rfverify's measures.\n")
        print("| file | contacts | Picard | Anderson | Anderson + friction continuation (where Anderson stops above 1e-8) "
              "| proven rounds | backward error | status | proven digits | recheck | time (s) |")
        print("|---|---:|---|---|---|---:|---:|---|---|---:|---:|")
        for spec in files(args.inputs):
            problem = rfverify.load(str(spec))
            name = Path(str(spec)).name
            print(row(name, problem, args.digits), flush=True)
            if args.three_d and problem.local is None and np.any(problem.mu_r > 0):
                print(row(name + " (3-D)", three_d(problem), args.digits), flush=True)


if __name__ == "__main__":
    main()
