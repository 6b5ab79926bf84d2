"""The physical problem at the edges of float64 and of the tool's own words: Φ's bounds over the
whole exponent range (recomputed in mpmath), exact zeros kept exact (all-zero data is its own
exact answer), the time limit a caller set named as set, the written /solution naming the
problem it answers, and ``info`` judging it as that problem's answer."""

from __future__ import annotations

import contextlib
import io
import json
from fractions import Fraction

import h5py
import mpmath
import numpy as np
import pytest
from hypothesis import example, given, strategies as st

import rfverify
from rfverify.cli import main
from rfverify.coulomb import backward
from rfverify.coulomb.result import STATEMENT

finite = st.floats(allow_nan=False, allow_infinity=False)


@given(a=finite, b=finite)
@example(a=1.3e200, b=1.1e200)  # the squares overflow unscaled
@example(a=1.7976931348623157e308, b=1.7976931348623157e308)  # so does the norm itself
@example(a=5e-324, b=0.0)
@example(a=1e-300, b=3e-310)  # the squares vanish unscaled
@example(a=1.0, b=1e-320)  # the smaller part lands in the subnormals when scaled
@example(a=0.0, b=-0.0)
def test_norm_bounds_hold_over_the_whole_exponent_range(a, b):
    lo, hi = (float(x[0]) for x in backward._norm_bounds(np.array([a]), np.array([b])))
    with mpmath.workprec(2200):  # exact for any two doubles' squares
        true = mpmath.sqrt(mpmath.mpf(a) ** 2 + mpmath.mpf(b) ** 2)
        assert mpmath.mpf(lo) <= true <= mpmath.mpf(hi)
        if a == 0 and b == 0:
            assert lo == hi == 0.0
        elif true > 1e-300 and np.isfinite(hi):
            assert hi <= lo * (1 + 1e-14), (lo, hi)  # tight where the result is a normal number


@given(x=finite, y=finite)
@example(x=1.0, y=1.0)
@example(x=0.0, y=0.0)
@example(x=1.0, y=1e-30)  # inexact: rounded to 1.0
def test_difference_bounds_are_exact_where_the_difference_is(x, y):
    lo, hi = (float(z[0]) for z in backward._difference_bounds(np.array([x]), np.array([y])))
    d = x - y
    if not np.isfinite(d):
        return
    true = Fraction(x) - Fraction(y)
    assert (lo == -np.inf or Fraction(lo) <= true) and (hi == np.inf or true <= Fraction(hi))
    assert (lo == hi) == (Fraction(d) == true)


def test_phi_is_exactly_zero_where_both_its_terms_are():
    p = rfverify.Problem.from_arrays(np.eye(3), np.c_[np.eye(3), np.zeros((3, 2))], [-1.0, 0.0, 0.0],
                                     np.zeros(5), [0.0], [0.0])
    lo, hi = backward.phi_bounds(p, np.array([0.5, 3.0, 4.0, 1.0, 1.0]))  # μ = μr = 0
    assert lo[0] == hi[0] == 0.0
    p2 = rfverify.Problem.from_arrays(np.eye(3), np.c_[np.eye(3), np.zeros((3, 2))], [-1.0, 0.0, 0.0],
                                      np.zeros(5), [0.7], [0.1])
    lo, hi = backward.phi_bounds(p2, np.array([0.5, 0.0, -0.0, 0.0, 0.0]))  # u_T = u_R = 0
    assert lo[0] == hi[0] == 0.0
    lo, hi = backward.phi_bounds(p2, np.array([0.5, 3.0, 4.0, 0.0, 0.0]))
    assert lo[0] <= 0.7 * 5 <= hi[0] and hi[0] > 0


def test_all_zero_data_is_its_own_exact_answer():
    """f = w = 0: v = u = r = 0 with shift 0 solves the physical problem exactly (δ = 0)."""
    rng = np.random.default_rng(3)
    H = np.zeros((6, 10))
    H[:, :3], H[:, 5:8] = rng.standard_normal((6, 3)), rng.standard_normal((6, 3))
    p = rfverify.Problem.from_arrays(np.eye(6), H, np.zeros(6), np.zeros(10), [0.5, 0.3], [0.0, 0.0])
    out = rfverify.solve_to_digits(p, digits=10, problem="coulomb")
    assert out.success, out.certificate.verdict
    assert out.backward_error == 0.0 and out.certificate.backward.relative == 0.0
    assert not np.any(out.v) and not np.any(out.r) and not np.any(out.u)


def test_huge_data_is_proven_in_exactly_scaled_units():
    """A sliding block with M·2⁻²³⁰, f·2³⁰⁰ (so u ~ 2⁵³⁰ ≈ 1e159, whose square overflows): the
    scaled problem is the same problem, and its backward error is proven (it overflowed before)."""
    H = np.c_[np.eye(3), np.zeros((3, 2))]
    p = rfverify.Problem.from_arrays(np.eye(3) * 2.0 ** -230, H, np.array([-1.0, 1.2, 1.6]) * 2.0 ** 300,
                                     np.zeros(5), [0.5], [0.0])
    out = rfverify.solve_to_digits(p, digits=10, problem="coulomb")
    assert out.certificate.backward.proven and out.success, out.certificate.verdict
    assert out.u[1] * 2.0 ** -530 == pytest.approx(1.2 * 0.75, rel=1e-9)  # the closed form, scaled


def _cli_json(args):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(args)
    return code, json.loads(buf.getvalue())


def test_a_time_limit_is_named_as_the_user_set_it():
    """The outer fixed point spends the limit; the proven round then runs on what is left (1 ms),
    which the verdict and the JSON named as 'the time limit' before."""
    code, out = _cli_json(["solve", "bundled:chute", "--problem", "coulomb", "--digits", "10",
                           "--time-limit", "0.05", "--json", "--quiet"])
    assert code == 1 and out["status"] in ("MaxTime", "NotCertified")
    text = json.dumps(out)
    assert '"time_limit": 0.001' not in text and "0.001 s" not in text
    assert out["time_limit"] == 0.05
    # not certified: the closing words do not call it a certificate
    assert "this is a backward-error certificate" not in out["verdict"]
    assert "a certificate of it is a backward-error one" in out["verdict"]


def test_written_solution_names_the_physical_problem_and_info_judges_it_so(tmp_path, capsys):
    path = tmp_path / "sol.h5"
    src = tmp_path / "block.hdf5"
    H = np.c_[np.eye(3), np.zeros((3, 2))]
    rfverify.save(rfverify.Problem.from_arrays(np.eye(3), H, [-1.0, 1.2, 1.6], np.zeros(5), [0.5], [0.0]), src)
    assert main(["solve", str(src), "--problem", "coulomb", "--digits", "10", "--out", str(path), "--quiet"]) == 0
    with h5py.File(path, "r") as fh:
        assert fh["solution"].attrs["problem"] == STATEMENT
        u = fh["solution/u"][()]
    capsys.readouterr()
    code, summary = _cli_json(["info", str(path), "--json"])
    sol = summary["solution"]
    assert code == 0 and sol["problem"] == "coulomb" and sol["consistent"], sol
    # the relaxation's check of the same answer fails: u_N = 0 while it slides (ũ_N > 0 is what K* needs)
    assert rfverify.check_solution(rfverify.load(str(path)), rfverify.load(str(path)).solution).dual_cone > 1e-3
    # independently: r ⊥ ũ with ũ = u + μ‖u_T‖e_N, u_N ≥ 0, from the file
    assert u[0] >= -1e-12 and abs(u[1] * 0.0 + np.hypot(u[1], u[2]) - 2.0 * 0.75) < 1e-9
    with h5py.File(path, "r+") as fh:  # a tampered answer: u_T off by 1e-3
        fh["solution/u"][1] += 1e-3
    _, summary = _cli_json(["info", str(path), "--json"])
    assert not summary["solution"]["consistent"] and "NOT a solution of it" in summary["solution"]["verdict"]


def test_a_start_file_is_never_written(tmp_path, capsys):
    """`--out` naming the `--start` file (or a link to it) replaced its /solution (an audit found
    it); it is refused now, before any work.  A start that is the problem file itself, written in
    place, is the problem's own in-place write and stays allowed."""
    import hashlib
    import os

    H = np.c_[np.eye(3), np.zeros((3, 2))]
    src = tmp_path / "block.hdf5"
    rfverify.save(rfverify.Problem.from_arrays(np.eye(3), H, [-1.0, 1.2, 1.6], np.zeros(5), [0.5], [0.0]), src)
    start = tmp_path / "start.h5"
    assert main(["solve", str(src), "--out", str(start), "--quiet"]) == 0
    link = tmp_path / "link.h5"
    os.symlink(start, link)
    before = hashlib.sha256(start.read_bytes()).hexdigest()
    for given in (start, link):
        assert main(["solve", str(src), "--problem", "coulomb", "--start", str(given), "--out", str(start),
                     "--quiet"]) == 2
    assert hashlib.sha256(start.read_bytes()).hexdigest() == before
    assert "is also an input of this command" in capsys.readouterr().err
    assert main(["solve", str(src), "--out", str(src), "--quiet"]) == 0  # the problem's own /solution
    assert main(["solve", str(src), "--problem", "coulomb", "--start", str(src), "--out", str(src), "--quiet"]) == 0
