"""Physical sanity check of generated scenes: do jqinv and Clarabel agree in v, and how
accurate is each, against the independent mpmath reference solution?

For every FCLIB file given (default: the committed example collection), both solvers run at
tol = 1e-10; each answer's stopping criterion is recomputed in longdouble from (v, u, r)
(:func:`rfverify.model.check.criterion`), and for problems with at most ``--max-contacts``
contacts the reference (:func:`reference.solve`, 50 digits, independent mode) gives each
answer's correct digits of v.  Digits are measured against
max(‖v_ref‖∞, ‖M⁻¹f‖∞): at rest (AllSticking, Lattice) v_ref is ~0 and a relative error of v
alone has no meaning, while the free velocity M⁻¹f is the problem's own velocity scale.
The contact-state mix (open / sticking / sliding / rolling) of the reference answer is
printed as well.  Not a test: it takes about a minute on the example collection.

    python benchmarks/scene_agreement.py
    python benchmarks/scene_agreement.py DIR_OR_FILES... --max-contacts 60
"""

from __future__ import annotations

import argparse
import sys
import math
from pathlib import Path

import numpy as np

import reference
import rfverify
from rfverify.bench.runner import BenchInputError, discover_problems
from rfverify.model.measures import measures
from rfverify.scenes.analysis import contact_state_mix, free_velocity

sys.path.insert(0, str(Path(__file__).parent))
from _results import recorded  # noqa: E402  (stamped results file)

DEFAULT = Path(__file__).resolve().parent.parent / "reports" / "example" / "problems" / "scenes"


def digits(x, x_ref, scale) -> float:
    err = float(np.abs(np.asarray(x) - np.asarray(x_ref)).max(initial=0.0))
    return math.inf if err == 0 else -math.log10(err / scale)


@recorded("scene_agreement")
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("paths", nargs="*", default=[str(DEFAULT)], help="problem files, directories of them or bundled:NAME")
    ap.add_argument("--tol", type=float, default=1e-10)
    ap.add_argument("--max-contacts", type=int, default=60, help="largest problem given to the reference")
    args = ap.parse_args(argv)
    try:  # the bench's own discovery: files, directories of them, bundled:NAME
        files = [Path(e.path) for e in discover_problems(args.paths)] if args.paths else []
    except BenchInputError as exc:
        ap.error(f"{exc}")
    head = (f"{'problem':36s} {'n':>4s} | {'jqinv':>13s} {'crit':>7s} {'dig':>5s} | {'clarabel':>20s} {'crit':>7s} "
            f"{'dig':>5s} | {'agree':>5s} | mix open/stick/slide/roll")
    print(head)
    print("-" * len(head))
    for path in files:
        p = rfverify.load(path)
        runs = {m: rfverify.solve(p, method=m, tol=args.tol) for m in ("jqinv", "clarabel")}
        crit = {m: measures(p, r.v, r.u, r.r, "longdouble").max for m, r in runs.items()}
        scale = max(float(np.abs(free_velocity(p)).max(initial=0.0)), np.finfo(float).tiny)
        d = {m: float("nan") for m in runs}
        mix = ""
        if p.n_contacts <= args.max_contacts:
            ref = reference.solve(p, dps=50)
            if ref.success:
                v_ref = ref.as_float("v")
                scale = max(scale, float(np.abs(v_ref).max(initial=0.0)))
                d = {m: digits(r.v, v_ref, scale) for m, r in runs.items()}
                c = contact_state_mix(p, v_ref, ref.as_float("u"), ref.as_float("r")).counts
                mix = f"{c['open']}/{c['sticking']}/{c['sliding']}/{c['rolling']}"
            else:
                mix = f"reference failed: {ref.message}"
        agree = digits(runs["jqinv"].v, runs["clarabel"].v, scale)
        print(f"{path.stem[:36]:36s} {p.n_contacts:4d} | {str(runs['jqinv'].status):>13s} {crit['jqinv']:7.1e} "
              f"{d['jqinv']:5.1f} | {str(runs['clarabel'].status):>20s} {crit['clarabel']:7.1e} "
              f"{d['clarabel']:5.1f} | {agree:5.1f} | {mix}", flush=True)
    print("\ncrit = recomputed criterion (≤ tol means verified solved); dig = correct digits of v against "
          "the reference, scaled by max(|v_ref|, |M⁻¹f|); agree = digits of agreement jqinv vs clarabel, same scale")


if __name__ == "__main__":
    main()
