"""The bound of one returned quantity (v, u, Hr or r) and what it says in digits
(:class:`QuantityBound`, :func:`quantity_bound`), the digits a float64 can carry, and the
outward-rounding helpers every bound uses (:func:`up`, :func:`down`, :func:`up_times`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.directed import bound_text, digits_text

FLOAT64_DIGITS = 53 * math.log10(2)  # ≈ 15.95: what a float64 can carry relative to its norm
MAX_CERTIFIABLE_DIGITS = 15
QUANTITIES = ("v", "u", "Hr", "r")
DATA_SCALE_NAMES = {"v": "‖M⁻¹f‖∞", "u": "‖HᵀM⁻¹f + w‖∞", "Hr": "‖f‖∞", "r": "‖f‖∞ / max_k ‖h_k‖₂"}
DATA_SCALE_NAMES_LOCAL = {"u": "‖q‖∞", "r": "‖q‖∞ / max_k W_kk"}


def up(x):
    return np.nextafter(np.asarray(x, dtype=np.float64), np.inf)


def up_times(x, eps: float):
    """x·eps rounded up, exactly 0 when eps is exactly 0 (a product with an exact zero is exact)."""
    return np.zeros_like(np.asarray(x, dtype=np.float64)) if eps == 0 else up(x * eps)


def down(x):
    return np.nextafter(np.asarray(x, dtype=np.float64), -np.inf)


@dataclass
class QuantityBound:
    """Proven error of one returned quantity (``v``, ``u``, ``Hr`` or ``r``).

    ``abs_bound`` ≥ ‖x − x*‖∞ (rigorous); ``norm`` = ‖x‖∞ of the returned vector;
    ``own_scale`` ≤ ‖x*‖∞ (rigorous, 0 when unknown); ``digits`` = −log10(abs_bound/own_scale)
    (None when own_scale ≤ abs_bound), capped at what float64 carries; ``mode`` is
    ``"relative"`` (digits against ‖x*‖∞), ``"absolute"`` (x* is zero at the requested
    accuracy: judged against ``data_scale``) or ``"information"`` (r where it is not unique).
    """

    name: str
    abs_bound: float
    norm: float
    own_scale: float
    data_scale: float
    data_scale_name: str
    digits: float | None
    mode: str
    certified: bool
    note: str = ""

    @property
    def zero_within(self) -> float:
        """Proven upper bound of ‖x*‖∞ (‖x‖∞ + abs_bound, rounded up; 0 when x = x* = 0 exactly)."""
        if not math.isfinite(self.abs_bound):
            return math.inf
        return 0.0 if self.norm == 0 and self.abs_bound == 0 else float(up(self.norm + self.abs_bound))

    @property
    def scale_digits(self) -> float | None:
        """−log10(zero_within / data_scale): how far below its data scale x* is proven to be
        (the absolute mode's measure; not significant digits of x*)."""
        z = max(self.zero_within, self.abs_bound)
        if z == 0:
            return FLOAT64_DIGITS
        if not (self.data_scale > 0 and math.isfinite(z)):
            return None
        return log_ratio(self.data_scale, z)

    def _not_relative(self) -> tuple[str, str] | None:
        """(short, long) words of a bound that is not in relative digits — not unique, exactly 0,
        or zero within a bound — else None."""
        n = self.name
        if self.mode == "information":
            bound = (f"|error| ≤ {bound_text(self.abs_bound)}, claimed for no digits" if math.isfinite(self.abs_bound)
                     else "error bound not available")
            # "not unique" only where that is proven (a verified self-stress); else only not proven unique
            words = "not unique" if self.note.startswith(f"{n} is not unique") else "not proven unique"
            return f"{n} {words}", f"{n}: {words} ({self.note}); {bound}"
        if self.mode == "absolute" and self.zero_within == 0:
            return f"{n} exactly 0", f"{n}: exactly 0 (the candidate's {n} is the solution's exactly: error bound 0)"
        if self.mode == "absolute":
            return (f"{n} zero within {bound_text(self.zero_within, 1)} ({digits_text(self.scale_digits)} digits of "
                    f"{self.data_scale_name})",
                    f"{n}: zero within {bound_text(self.zero_within)} (‖{n}*‖∞ ≤ {bound_text(self.zero_within)} = "
                    f"{digits_text(self.scale_digits)} digits below the data scale {self.data_scale_name} = "
                    f"{self.data_scale:.2e}; |error| ≤ {bound_text(self.abs_bound)}; no significant digits are claimed)")
        return None

    def short(self) -> str:
        """One phrase that claims exactly what was proven: relative digits, or "zero within"."""
        words = self._not_relative()
        if words is not None:
            return words[0]
        return (f"{self.name} {digits_text(self.digits)} digits" if self.digits is not None
                else f"{self.name} no relative digits")

    def describe(self) -> str:
        words = self._not_relative()
        if words is not None:
            return words[1]
        d = "no relative digits" if self.digits is None else f"{digits_text(self.digits)} digits"
        extra = f"; {self.note}" if self.note and not self.certified and self.digits is None else ""
        return (f"{self.name}: {d} (|error| ≤ {bound_text(self.abs_bound)}, ‖{self.name}*‖∞ ≥ "
                f"{bound_text(self.own_scale, upper=False)})"
                + extra)

    def as_dict(self) -> dict:
        return {"abs_bound": self.abs_bound, "norm": self.norm, "own_scale": self.own_scale,
                "data_scale": self.data_scale, "data_scale_name": self.data_scale_name,
                "digits": self.digits, "mode": self.mode, "certified": self.certified, "note": self.note}


def validate_digits(digits) -> int:
    """Requested digits must be an integer in [1, 15]: a float64 carries at most 15.95."""
    from ..errors import InvalidArgumentError

    if isinstance(digits, bool) or not isinstance(digits, (int, np.integer)):
        if isinstance(digits, float) and digits.is_integer():
            digits = int(digits)
        else:
            raise InvalidArgumentError("digits", f"must be an integer, got {digits!r}",
                                       fix=f"ask for 1 … {MAX_CERTIFIABLE_DIGITS} digits, e.g. digits=10")
    digits = int(digits)
    if not 1 <= digits <= MAX_CERTIFIABLE_DIGITS:
        raise InvalidArgumentError("digits", f"is {digits}; a float64 solution carries at most "
                                             f"{FLOAT64_DIGITS:.2f} significant digits",
                                   fix=f"ask for 1 … {MAX_CERTIFIABLE_DIGITS} digits")
    return digits


def log_ratio(big: float, small: float) -> float:
    """log10(big / small) for positive finite floats, without forming a ratio that under- or
    overflows (a bound of 1e-300 on a vector of norm 1e300)."""
    return math.log10(big) - math.log10(small)


def quantity_bound(name, e, x, scales, requested, note="", names=DATA_SCALE_NAMES, relative: bool = False) -> QuantityBound:
    """The record of one quantity.  ``relative=True`` accepts only relative digits: a quantity
    whose x* may be zero is then not certified (its relative digits are meaningless)."""
    e_inf = float(np.max(e, initial=0.0))
    norm = float(np.max(np.abs(x), initial=0.0))
    own = max(float(down(norm - e_inf)), 0.0) if math.isfinite(e_inf) else 0.0
    data = scales[name]
    digits = None
    if own > e_inf and e_inf >= 0:
        digits = min(FLOAT64_DIGITS, log_ratio(own, e_inf)) if e_inf > 0 else FLOAT64_DIGITS
    tol = 10.0 ** (-requested)
    if digits is not None and digits >= requested:
        return QuantityBound(name, e_inf, norm, own, data, names[name], digits, "relative", True, note)
    if e_inf == 0 and norm == 0 and not relative:
        # The bound is 0 and x = 0: x* = 0 exactly, whatever the data scale (the all-zero problem).
        return QuantityBound(name, 0.0, 0.0, 0.0, data, names[name], None, "absolute", True,
                             note or f"{name}* = 0 exactly (error bound 0)")
    if relative:
        if digits is None and e_inf == 0 and norm == 0:
            note = note or (f"relative digits requested, but {name}* = 0 exactly (error bound 0): "
                            "a zero has no relative digits")
        elif digits is None:
            note = note or (f"relative digits requested, but ‖{name}*‖∞ may be 0 (‖{name}‖∞ = {norm:.2e} ≤ "
                            f"error bound {bound_text(e_inf)}): relative digits are meaningless here")
        return QuantityBound(name, e_inf, norm, own, data, names[name], digits, "relative", False, note)
    # x* may be zero: judge absolutely against the data scale when it is negligible there.
    limit = float(down(float(down(tol)) * data))  # ≤ 10⁻ᵏ·scale exactly
    if data > 0 and float(up(norm + e_inf)) <= limit and e_inf <= limit:
        return QuantityBound(name, e_inf, norm, own, data, names[name], digits, "absolute", True,
                             note or f"‖{name}*‖∞ ≤ {bound_text(float(up(norm + e_inf)))} ≤ 1e-{requested}·{names[name]}")
    return QuantityBound(name, e_inf, norm, own, data, names[name], digits, "relative", False, note)
