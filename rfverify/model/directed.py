"""Proven figures in words: a bound printed so that its "≤" or "≥" still holds, and proven
digits printed without rounding up (plain formatting rounds to nearest)."""

from __future__ import annotations

import math


def bound_text(x: float, places: int = 2, *, upper: bool = True) -> str:
    """``x`` in e-format with ``places`` decimals, rounded outward: up for an upper bound (the
    smallest such number ≥ x), down for a lower bound, so that a printed "≤" or "≥" still holds
    (plain formatting rounds to nearest: |error| ≤ 1.874999e-06 printed as "≤ 1.87e-06")."""
    from decimal import ROUND_CEILING, ROUND_FLOOR, Context, Decimal

    if not math.isfinite(x) or x == 0:
        return f"{x:.{places}e}"
    q = Context(prec=places + 1, rounding=ROUND_CEILING if upper else ROUND_FLOOR).plus(Decimal(x))  # exact input
    sign, digits, _ = q.as_tuple()
    digits = "".join(map(str, digits)).ljust(places + 1, "0")[:places + 1]
    e = q.adjusted()
    mantissa = digits[0] + ("." + digits[1:] if places else "")
    return f"{'-' if sign else ''}{mantissa}e{'-' if e < 0 else '+'}{abs(e):02d}"


def digits_text(d: float) -> str:
    """Proven digits printed to one decimal, rounded down (5.99999 is "5.9", not "6.0", beside
    "not proven to 6 digits"); within 1e-9 of a tenth it is that tenth (the count is a float)."""
    return f"{math.floor(d * 10 + 1e-9) / 10:.1f}"
