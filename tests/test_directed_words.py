"""Printed bounds keep their direction: "|error| ≤ X" with X ≥ the bound, "‖x*‖∞ ≥ Y" with Y ≤ it,
proven digits never rounded up (an audit found "≤ 1.87e-06" for 1.87499…e-06, "≥ 2.60e+01" for
25.95 and "not proven to 6 digits: v has 6.0 proven digits" for 5.99999)."""

from __future__ import annotations

from decimal import Decimal

from hypothesis import example, given, strategies as st

from rfverify.model.directed import bound_text, digits_text
from rfverify.proof.quantity import QuantityBound

positive = st.floats(min_value=5e-324, max_value=1.7e308, allow_nan=False, allow_infinity=False)


def _ulp(text: str) -> Decimal:
    mantissa, exp = text.split("e")
    places = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return Decimal(10) ** (int(exp) - places)


@given(x=positive, places=st.integers(0, 4))
@example(x=1.8749999999290e-06, places=2)
@example(x=25.9512, places=2)
@example(x=9.9999e5, places=2)  # rounds up into the next decade
@example(x=5e-324, places=2)
def test_bounds_are_printed_outward_and_as_tight_as_their_digits(x, places):
    up, down = bound_text(x, places), bound_text(x, places, upper=False)
    assert Decimal(up) >= Decimal(x) > Decimal(up) - _ulp(up)
    assert Decimal(down) <= Decimal(x) < Decimal(down) + _ulp(down)
    assert float(up) == float(f"{x:.{places}e}") or Decimal(up) > Decimal(f"{x:.{places}e}")
    assert bound_text(-x, places) == "-" + bound_text(x, places, upper=False)  # −x's upper bound


def test_proven_digits_are_never_rounded_up():
    assert digits_text(5.99999) == "5.9" and digits_text(6.0) == "6.0"
    assert digits_text(10.2) == "10.2" and digits_text(10.66) == "10.6"


def test_a_quantity_prints_its_bounds_outward():
    q = QuantityBound("u", abs_bound=1.8749999999290e-06, norm=26.0, own_scale=25.9512, data_scale=30.0,
                      data_scale_name="‖u‖", digits=5.99999, mode="relative", certified=False)
    text = q.describe()
    assert "|error| ≤ 1.88e-06" in text and "‖u*‖∞ ≥ 2.59e+01" in text and "5.9 digits" in text
    assert q.short() == "u 5.9 digits"
