"""What the commands share: exit codes, the PROBLEM argument and its load options, loading,
strict JSON output, progress lines and recorded warnings."""

from __future__ import annotations

import argparse
import contextlib
import math
from pathlib import Path
import sys
import warnings

from ..errors import RfverifyError
from ..model.lifting import cone_words
from .argtypes import nonneg_float

EXIT_OK = 0
EXIT_NOT_SOLVED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERNAL = 3


DOCS_DIR = Path(__file__).resolve().parent.parent / "docs"
"""The documents ``--help`` cites (DESIGN.md, TUTORIAL.md, REFERENCE.md, ...), installed with the
package (package data: ``rfverify/docs`` is the repository's ``docs/``)."""

DOCS_NOTE = f"DESIGN §k and the other documents named here are installed with rfverify in {DOCS_DIR}."


def exit_codes(success: str, failure: str | None = None, extra: str = "") -> str:
    """The ``--help`` epilog of a command: its exit codes, in one sentence."""
    codes = [f"0 {success}"] + ([f"1 {failure}"] if failure else [])
    codes += ["2 bad input or arguments (one line on stderr naming the file, field and fix)",
              "3 internal error (a bug: please report it)", "130 interrupted",
              "141 stdout closed early (e.g. | head)"]
    return "Exit codes: " + "; ".join(codes) + (f"; {extra}" if extra else "") + "."

PROBLEM_HELP = ("problem file: FCLIB .hdf5 (fclib_global_rolling, fclib_global, fclib_local) or Siconos "
                ".dat (RFC3D/GRFC3D rolling, FC3D/GFC3D 3-D Coulomb; a local problem is solved through its lifting to global form and proven on its own "
                "W), or bundled:NAME for a problem shipped with rfverify "
                "(bundled:chute, bundled:chute-dat, bundled:sphere, bundled:cube, "
                "bundled:sphere-from-global)")


def add_load_options(p: argparse.ArgumentParser):
    p.add_argument("--max-asymmetry", type=nonneg_float, default=None, metavar="X",
                   help="largest accepted entrywise asymmetry max|M_ij - M_ji|/sqrt(M_ii M_jj) "
                        "before M (W of a local problem) is refused (default: 1e-2; 'inf' accepts "
                        "any); the refusal and 'info' also show the normwise "
                        "||M - Mᵀ||_F/||M||_F. An accepted M is symmetrised as (M + Mᵀ)/2.")


AS_STORED_HELP = ("solve and prove the equations with M (W of a local file) exactly as stored, instead of "
                  "(M + Mᵀ)/2, the convention of Siconos and FCLIB and the default; the two differ only when "
                  "the stored matrix is unsymmetric, and a verdict about (M + Mᵀ)/2 then also states how many "
                  "digits of the stored equations' solution the answer has (DESIGN §6.1). Not with the peers "
                  "clarabel and siconos, nor for a local file with an unsymmetric W")


def add_equations_option(p: argparse.ArgumentParser):
    """``--as-stored``: the equations with the stored, unsymmetric matrix (solve, certify, bench)."""
    p.add_argument("--as-stored", action="store_true", help=AS_STORED_HELP)


def add_run_limits(p: argparse.ArgumentParser, *, tol_help: str, max_iter_help: str) -> None:
    """``--tol T`` and ``--max-iter K`` of a command that runs Algorithm 1 (solve, diagnose); the
    help says what they bound there."""
    from .argtypes import positive_int, tolerance

    p.add_argument("--tol", type=tolerance, default=1e-10, metavar="T", help=tol_help)
    p.add_argument("--max-iter", type=positive_int, default=100, metavar="K", help=max_iter_help)


PSD_SHIFT_HELP = ("for a local file whose W is not positive semidefinite as stored (rounding in Siconos's "
                  "W = H M⁻¹ Hᵀ; nothing about such a file can be proven): solve and prove W + D instead, D ≥ 0 "
                  "diagonal (the smallest power of two, from about 4·|λmin(W)|, that a verified test proves "
                  "enough; refused above 1e-8·‖W‖, and a W farther from PSD than the rounding of the file's values explains is refused as it is read). Every claim then names W + D, and a solution (u, r) of it "
                  "solves the file's W exactly for q + D r: a backward error, which --problem coulomb adds to "
                  "its bound. Nothing changes for a W that is PSD as stored")


def end_problem_command(p: argparse.ArgumentParser, func, check_outputs) -> None:
    """What a command that poses a problem's equations ends with (solve, certify): ``--as-stored``,
    ``--psd-shift``, the load options, and the functions that check its outputs and run it."""
    add_equations_option(p)
    p.add_argument("--psd-shift", action="store_true", help=PSD_SHIFT_HELP)
    add_load_options(p)
    p.set_defaults(func=func, check_outputs=check_outputs)


def load_problem(args):
    """The PROBLEM argument loaded with the load options, its W shifted where ``--psd-shift`` asks
    (:func:`rfverify.proof.psd_shift.shift_to_psd`), posing the equations ``--as-stored`` asks for
    (where the command has those options)."""
    from ..io import load
    from ..model.problem import DEFAULT_MAX_ASYMMETRY

    limit = DEFAULT_MAX_ASYMMETRY if args.max_asymmetry is None else args.max_asymmetry
    problem = load(args.problem, max_asymmetry=limit)
    if getattr(args, "psd_shift", False):
        from ..proof.psd_shift import shift_to_psd

        problem = shift_to_psd(problem)
    if getattr(args, "as_stored", False):
        from ..solver import posed

        problem = posed(problem, True, getattr(args, "method", None))
    return problem


@contextlib.contextmanager
def recorded_warnings():
    """Record warnings (numpy floating-point, ...) instead of letting Python print them."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught


def warning_summary(caught) -> list[str]:
    """Distinct warnings with their counts, e.g. ``"RuntimeWarning: overflow in add (×13)"``."""
    counts = {}
    for w in caught:
        key = f"{w.category.__name__}: {' '.join(str(w.message).split())}"
        counts[key] = counts.get(key, 0) + 1
    return [f"{k} (×{n})" if n > 1 else k for k, n in counts.items()]


def print_warnings(items, where: str) -> None:
    if items:
        print(f"numerical warnings {where}: {'; '.join(items)}")


def dumps(obj, **kwargs) -> str:
    """Strict JSON (non-finite numbers as null): what every --json output prints."""
    from ..io.output import dumps as strict_dumps

    return strict_dumps(obj, **kwargs)


def progress_printer(args):
    """One line per stage on stderr, unless --json or --quiet."""
    if getattr(args, "json", False) or getattr(args, "quiet", False):
        return None

    def say(message):
        print(f"rfverify {args.command}: {message}", file=sys.stderr, flush=True)

    return say


PROGRESS_AFTER_ENV = "RFVERIFY_PROGRESS_AFTER"
"""Seconds of a run after which ``solve`` prints its iterations on stderr (default
:data:`PROGRESS_AFTER`; 0: from the first iteration)."""

PROGRESS_AFTER = 2.0
PROGRESS_EVERY = 0.5
"""At most one iteration line per this many seconds (a new form or component is always shown)."""


def progress_after() -> float:
    """The threshold of :data:`PROGRESS_AFTER_ENV` in seconds, refused with the fix when it is not
    a number ≥ 0."""
    import os

    from ..errors import InvalidArgumentError

    raw = os.environ.get(PROGRESS_AFTER_ENV, "").strip()
    if not raw:
        return PROGRESS_AFTER
    try:
        seconds = float(raw)
    except ValueError:
        seconds = math.nan
    if not (seconds >= 0 and math.isfinite(seconds)):
        raise InvalidArgumentError(PROGRESS_AFTER_ENV, f"must be a number of seconds ≥ 0, got {raw!r}",
                                   fix=f"set {PROGRESS_AFTER_ENV}={PROGRESS_AFTER:g} (the default) or unset it")
    return seconds


class IterationProgress:
    """A ``callback`` of :func:`rfverify.solve` that shows a long run as it goes: once ``after``
    seconds have passed since ``start``, one line per iteration through ``say`` — the form, the
    iteration, μ and the criterion (DESIGN §4.5), and the step that led to that iterate ("full
    step", or its length and the cone whose boundary cut it short), as the extended phase's
    lines say it — at most one per :data:`PROGRESS_EVERY` seconds except when the form (``auto``
    moving on) or the component changes.  Never stops the run."""

    def __init__(self, say, after: float, start: float | None = None, every: float = PROGRESS_EVERY):
        import time

        self.say, self.after, self.every = say, after, every
        self.start = time.perf_counter() if start is None else start
        self.last, self.key = -math.inf, None
        self.previous = None  # the info of the last call, shown or not: it holds the step to this one

    def __call__(self, info) -> bool:
        import time

        before, self.previous = self.previous, info
        now = time.perf_counter()
        if now - self.start < self.after:
            return False
        key = (info.method, info.component)
        if key == self.key and now - self.last < self.every:
            return False
        self.key, self.last = key, now
        # numbered from 0, as in the JSON and the --verbose table; named wherever the problem was split
        where = f" (component {info.component})" if getattr(info, "components", 1) > 1 else ""
        self.say(f"  {info.method or 'Algorithm 1'} iteration {info.iteration}{where}: μ = {info.mu:.2e}, "
                 f"criterion = {info.criterion:.2e}, {now - self.start:.1f} s{_step_to(before, info)}")
        return False


def _step_to(before, info) -> str:
    """"; step 0.604, held by contact 623's rolling cone (reaction)", "; full step", or "" (the
    first iteration of a run): the step from ``before``, the previous iteration's info, to
    ``info``'s iterate."""
    if before is None or (before.method, before.component, before.iteration + 1) != (
            info.method, info.component, info.iteration):
        return ""
    if before.alpha >= 1.0:
        return "; full step"
    held = getattr(before, "held_by", None)
    return f"; step {before.alpha:.3g}" + (f", held by {cone_words(held)}" if held and "contact" in held else "")


def print_quantities(cert) -> None:
    for q in cert.quantities.values():
        print("  " + q.describe())


def is_hdf5_input(spec) -> bool:
    from ..io import resolve_path

    try:
        with open(resolve_path(spec), "rb") as fh:
            return fh.read(8) == b"\x89HDF\r\n\x1a\n"
    except (OSError, RfverifyError):
        return False


def same_problem(problem, other) -> bool:
    """True when the two problems have the same M, H, f, w, mu and mu_r, exactly."""
    import numpy as np

    return (problem.M.shape == other.M.shape and problem.H.shape == other.H.shape
            and all(np.array_equal(getattr(problem, k), getattr(other, k)) for k in ("f", "w", "mu", "mu_r"))
            and (problem.M != other.M).nnz == 0 and (problem.H != other.H).nnz == 0)


def require_same_problem(problem, other, path):
    """A solution is only certified against the problem it was computed for."""
    from ..errors import InvalidProblemError

    if not same_problem(problem, other):
        sizes = (other.n_dofs, other.n_contacts) != (problem.n_dofs, problem.n_contacts)
        raise InvalidProblemError(
            "solution", f"{path} holds a different problem " + (
                f"(m = {other.n_dofs}, n = {other.n_contacts} vs m = {problem.n_dofs}, n = {problem.n_contacts})"
                if sizes else f"(the same sizes, m = {problem.n_dofs}, n = {problem.n_contacts}, other data)"),
            fix="pass the solution file written for this problem (rfverify solve ... --out)")
