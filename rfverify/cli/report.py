"""``rfverify report``: report.html and summary.md of a bench run directory (the work is
:func:`rfverify.report.make_report`)."""

from __future__ import annotations

import sys

from .argtypes import nonneg_int, positive_int, witness_digits
from .common import exit_codes, EXIT_OK, dumps, progress_printer

HELP = "write RUN_DIR/report.html and RUN_DIR/summary.md from a bench run"

DESCRIPTION = """\
Build the report of a bench run directory. Its first screen: one figure, the proven digits of
every saved answer of every method against its run time (the rigorous bound of DESIGN §6,
evaluated exactly at each problem's proven point from its --digits path and carried to the
answer; cached in RUN_DIR/proven/), and the answers to which method reaches K proven digits,
how fast, where double precision breaks and what the K-digit path costs. Below: robustness and
refuted solver claims (grouped, each once), speed on common solved sets, Dolan–Moré profiles,
how far double precision gets, cond(Q_p) and λ2 per iteration for one hard problem per family,
the proven digits of every method, lockstep diagnostics (double against reference) of the worst
cases, and every other failure with its diagnosed cause. Where RUN_DIR holds runs of `bench
--problem coulomb`, a section on the physical problem follows the first screen: per answer
(rfverify's, and Siconos GFC3D_IPM's), certified or not, its proven backward error, proven digits,
iterations and time, or why it has none (a RUN_DIR with those runs only gets that section
alone). report.html stands alone (its figures
are embedded in it, nothing beside it is needed to view it); the figures are also written as PNG
files into RUN_DIR, where summary.md links them."""


def add_parser(sub) -> None:
    """The ``report`` subcommand."""
    report = sub.add_parser("report", help=HELP, description=DESCRIPTION,
                            epilog=exit_codes("the report was written"))
    report.add_argument("run_dir", metavar="RUN_DIR")
    report.add_argument("--diagnose", type=nonneg_int, default=3, metavar="N",
                        help="lockstep-diagnose the N worst cases (default: %(default)s; 0 skips)")
    report.add_argument("--diagnose-max-contacts", type=positive_int, default=40, metavar="N",
                        help="only diagnose problems with at most N contacts (default: %(default)s)")
    report.add_argument("--dps", type=witness_digits, default=40, metavar="D",
                        help="digits of the mpmath witness of each diagnosis, at least 34 (default: %(default)s)")
    report.add_argument("--quiet", action="store_true", help="no progress output")
    report.add_argument("--json", action="store_true", help="print paths and counts as JSON")
    report.set_defaults(func=cmd_report)


def cmd_report(args) -> int:
    from ..compilation import announcing
    from ..report import make_report

    with announcing(progress_printer(args)):  # its proofs and lockstep runs may compile kernels
        out = make_report(args.run_dir, diagnose_count=args.diagnose,
                          diagnose_max_contacts=args.diagnose_max_contacts, diagnose_dps=args.dps,
                          quiet=args.quiet)
    if out["issues"]:
        first = out["issues"][0].split("; fix:")[0]
        print(f"rfverify report: warning: {args.run_dir}: {len(out['issues'])} record(s) or array "
              f"file(s) missing or damaged, e.g. {first} (all listed in summary.md under 'Missing or "
              "damaged records'); fix: re-run the bench command, which redoes them", file=sys.stderr)
    if args.json:
        print(dumps({"report": out["report"], "summary": out["summary"], "issues": out["issues"],
                      "bench_running": out["running"],
                      "counts": [{"collection": c, "method": m, "tol": t, "solved": s, "total": n}
                                 for (c, m, t), (s, n) in out["counts"].items()]}))
    else:
        print(f"report: {out['report']}\nsummary: {out['summary']}")
    return EXIT_OK
