"""The Python API as documented, at its edges (found by an audit of the result objects and their
docs): a time limit spent before the first form, bad settings, complex data, forms the
diagnosis cannot follow, the Coulomb headline where a quantity is only bounded absolutely, a
certify search cut short, and a repr of at most four lines."""

from __future__ import annotations

import numpy as np
import pytest

import rfverify
from rfverify.errors import InvalidArgumentError, InvalidProblemError


@pytest.fixture(scope="module")
def chute():
    return rfverify.load("bundled:chute")


def test_a_time_limit_spent_before_the_first_form_is_max_time(chute):
    """auto raised ValueError (min() of no results) where the limit ran out before its first form."""
    res = rfverify.solve(chute, time_limit=1e-9)
    assert res.status == "MaxTime" and not res.success
    assert "time limit of 1e-09 s" in res.message and res.settings.time_limit == 1e-9


@pytest.mark.parametrize("setting", [dict(start="x"), dict(gamma0=2), dict(sigma_rule=3), dict(refine_max="a"),
                                     dict(stall_iterations=0), dict(max_components=0), dict(split_components="yes"),
                                     dict(almost_factor=0.5)])
def test_a_bad_setting_is_refused_by_name_with_the_fix(setting):
    name = next(iter(setting))
    with pytest.raises(InvalidArgumentError, match=name) as err:
        rfverify.solve(rfverify.load("bundled:sphere"), **setting)
    assert "fix:" in str(err.value)


def test_complex_data_is_refused_not_truncated():
    H = np.c_[np.eye(3), np.zeros((3, 2))]
    with pytest.raises(InvalidProblemError, match="complex"):
        rfverify.Problem.from_arrays(np.eye(3), H, np.array([-1.0, 0.5, 0.0]) + 1e-3j, np.zeros(5), [0.3], [0.0])
    with pytest.raises(InvalidProblemError, match="complex"):
        rfverify.Problem.from_arrays(np.eye(3) * (1 + 0j), H, [-1.0, 0.5, 0.0], np.zeros(5), [0.3], [0.0])


def test_the_diagnosis_and_the_path_name_what_they_cannot_run():
    from rfverify.verify.diagnosis import diagnose

    sphere = rfverify.load("bundled:sphere")
    with pytest.raises(InvalidArgumentError, match="method"):
        diagnose(sphere, method="clarabel")
    with pytest.raises(InvalidArgumentError, match="backend"):
        rfverify.solve_to_digits(sphere, backend="x")


def test_a_coulomb_answer_with_a_quantity_bounded_absolutely_is_not_proven_to_k_digits(chute):
    """DESIGN §6.3: 'proven to K digits' only when every quantity has K relative digits."""
    answer = rfverify.solve(chute, problem="coulomb")
    cert = rfverify.certify(chute, answer, problem="coulomb", digits=4)
    absolute = [name for name, q in cert.quantities.items() if q.mode == "absolute"]
    assert cert.certified and absolute == ["r"]  # r at the Chute's sliding contacts: zero within 6.1e-04
    assert cert.verdict.startswith("certified (4 digits requested; zero quantities bounded absolutely")
    assert len(repr(answer).splitlines()) <= 4  # RESULTS.md: a repr of at most four lines


def test_a_certify_search_cut_short_says_so_even_where_the_candidate_itself_is_kept(chute):
    cert = rfverify.certify(chute, rfverify.solve(chute, tol=1e-8), digits=8, time_limit=1e-6)
    assert cert.status == "MaxTime" and "time limit" in cert.verdict


def test_arguments_of_the_wrong_kind_are_named_not_python_errors_from_deep_inside():
    sphere = rfverify.load("bundled:sphere")
    answer = rfverify.solve(sphere)
    for call, name in ((lambda: rfverify.solve(sphere, callback=3), "callback"),
                       (lambda: rfverify.solve(sphere, keep_iterates="x"), "keep_iterates"),
                       (lambda: rfverify.certify(sphere, answer, point=5), "point"),
                       (lambda: rfverify.check_solution(sphere, None), "solution"),
                       (lambda: rfverify.check_solution(sphere, (answer.v, answer.u, answer.r)), "solution")):
        with pytest.raises(InvalidArgumentError, match=name) as err:
            call()
        assert "fix:" in str(err.value)
    assert rfverify.check_solution(sphere, answer).ok(1e-8)  # a result is still a solution to check


def test_a_problem_built_without_validation_is_refused_by_name():
    """Audit (2026-12-08): rfverify.Problem(M=…, …) skips from_arrays' validation, and solve then
    failed with AttributeError: 'NoneType' object has no attribute 'labels' (for valid data too)."""
    p = rfverify.load("bundled:chute")
    bare = rfverify.Problem(M=p.M, H=p.H, f=p.f, w=p.w, mu=p.mu, mu_r=p.mu_r)
    for call in (rfverify.solve, rfverify.solve_to_digits, rfverify.diagnose):
        with pytest.raises(rfverify.InvalidArgumentError, match="from_arrays"):
            call(bare)
