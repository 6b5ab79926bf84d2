"""Benchmarks: every method on every problem at every tolerance, in parallel processes, each
run counted as solved only after an independent high-precision recheck (:mod:`.verify`).

``run_bench`` writes a run directory (see :mod:`.runner`); :mod:`rfverify.report` turns it into
``report.html`` and ``summary.md``.
"""

from ..errors import BenchInputError
from .runner import discover_problems, plan_tasks, run_bench
from .verify import HighPrecisionChecker, forward_digits, verified_criterion

__all__ = ["run_bench", "discover_problems", "plan_tasks", "BenchInputError", "HighPrecisionChecker",
           "verified_criterion", "forward_digits"]
