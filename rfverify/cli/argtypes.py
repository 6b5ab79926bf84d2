"""Argument types of the ``rfverify`` command line: each turns one option's text into its value
or raises ``argparse.ArgumentTypeError`` with what is wrong (argparse then exits 2 with one line)."""

from __future__ import annotations

import argparse
import math


def number(text: str) -> float:
    """A float, not NaN."""
    try:
        val = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number; fix: give a decimal number, e.g. 1e-10") from None
    if math.isnan(val):
        raise argparse.ArgumentTypeError("NaN is not allowed; fix: give a decimal number, e.g. 1e-10")
    return val


def nonneg_float(text: str) -> float:
    val = number(text)
    if not val >= 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be ≥ 0; fix: give a number ≥ 0")
    return val


def positive_float(text: str) -> float:
    val = number(text)
    if not val > 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be > 0; fix: give a number > 0, e.g. 1e-10")
    return val


def seconds(text: str) -> float:
    """A time limit in seconds: a number > 0 (inf: none)."""
    val = number(text)
    if not val > 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be > 0 seconds; fix: give a number of seconds > 0, e.g. 600")
    return val


def tolerance(text: str) -> float:
    """A tolerance: a finite number > 0 (inf would stop at once and call anything solved)."""
    val = positive_float(text)
    if math.isinf(val):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number > 0; fix: give e.g. 1e-10")
    return val


def _integer(text: str, *, least: int) -> int:
    try:
        val = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer; fix: give a whole number ≥ {least}") from None
    if val < least:
        raise argparse.ArgumentTypeError(f"{text!r} must be ≥ {least}; fix: give a whole number ≥ {least}")
    return val


def nonneg_int(text: str) -> int:
    return _integer(text, least=0)


def positive_int(text: str) -> int:
    return _integer(text, least=1)


def witness_digits(text: str) -> int:
    """D of diagnose's and report's --dps: the mpmath witness checks double-double steps (about
    32 digits), so at least :data:`rfverify.verify.lockstep.WITNESS_MIN_DPS`; and of certify's
    --cross-check reference, which must be far more accurate than the float64 answer it measures."""
    return _integer(text, least=34)


def digit_count(text: str) -> int:
    """K of --digits: 1 … 15 (what the proof can show in double-double)."""
    from ..errors import InvalidArgumentError
    from ..proof import validate_digits

    try:
        return validate_digits(int(text))
    except ValueError as exc:
        if isinstance(exc, InvalidArgumentError):
            raise argparse.ArgumentTypeError(f"{exc.problem}; fix: {exc.fix}") from None
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer; fix: give K in 1 … 15") from None


def out_path(text: str) -> str:
    """An output path: not empty (an empty --out would silently write nothing)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path writes nothing; give a file name or "
                                         "leave the option out")
    return text


def scene_name(text: str) -> str:
    """A scene of :mod:`rfverify.scenes`, case-insensitive."""
    from ..scenes import resolve_scene
    from ..scenes.stepper import SceneError

    try:
        return resolve_scene(text).name
    except SceneError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def method_list(text: str) -> list:
    """Comma-separated method names of :data:`rfverify.solver.result.METHODS`, without repeats."""
    from ..solver.result import METHODS

    items = [t.strip() for t in text.split(",") if t.strip()]
    bad = [t for t in items if t not in METHODS]
    if bad or not items:
        raise argparse.ArgumentTypeError(f"unknown method(s) {', '.join(bad) or '(none given)'}; "
                                         f"choose from {', '.join(METHODS)}")
    return list(dict.fromkeys(items))


def tol_list(text: str) -> list:
    """Comma-separated tolerances, largest first, without repeats."""
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise argparse.ArgumentTypeError("give at least one tolerance")
    return sorted({tolerance(t) for t in items}, reverse=True)
