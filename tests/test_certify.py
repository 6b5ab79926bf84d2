"""Certification: a false certificate is the worst bug this project can have."""

from __future__ import annotations

import json

import h5py
import mpmath
import numpy as np
import pytest

import reference
import rfverify
from rfverify.certification import certify, high_precision_residuals
from rfverify.cli import main
from rfverify.solver import solve


@pytest.fixture(scope="module")
def chute_ref():
    problem = rfverify.load("bundled:chute")
    return problem, reference.solve(problem, dps=50)


def test_reference_rounded_to_double_certifies_at_10(chute_ref):
    problem, ref = chute_ref
    cert = certify(problem, ref.as_float("v"), ref.as_float("u"), ref.as_float("r"), digits=10)
    assert cert.certified, cert.verdict
    assert min(cert.digits.values()) >= 14  # rounding to double loses nothing else


@pytest.mark.parametrize("which", ["v", "u", "r"])
def test_eighth_digit_perturbation_is_not_certified_at_10(chute_ref, which):
    problem, ref = chute_ref
    x = {k: ref.as_float(k) for k in ("v", "u", "r")}
    rng = np.random.default_rng(0)
    big = np.abs(x[which]) >= 0.1 * np.abs(x[which]).max()
    # Change the 8th significant digit of the largest entries (relative 3e-8 > 1e-10).
    x[which] = np.where(big, x[which] * (1 + 3e-8 * rng.choice([-1, 1], x[which].shape)), x[which])
    cert = certify(problem, x["v"], x["u"], x["r"], digits=10, always_reference=True)
    assert not cert.certified, cert.verdict
    assert cert.certified is False
    cert7 = certify(problem, x["v"], x["u"], x["r"], digits=7, always_reference=True)
    assert cert7.certified, cert7.verdict  # still right to 7 digits: the claim tracks the truth


def test_double_solution_digits_are_measured(chute_ref):
    problem, ref = chute_ref
    res = solve(problem, method="jqinv", tol=1e-10)
    cert10 = certify(problem, res.v, res.u, res.r, digits=10)
    assert not cert10.certified
    cert5 = certify(problem, res.v, res.u, res.r, digits=5)
    assert cert5.certified, cert5.verdict
    # The claimed digits are what an independent comparison gives.
    v_ref = np.array([float(x) for x in ref.v])
    err = np.max(np.abs(res.v - v_ref)) / np.max(np.abs(v_ref))
    assert cert5.digits["v"] == pytest.approx(-np.log10(err), abs=1e-6)


def test_stored_zero_solution_is_refused_cheaply():
    problem = rfverify.load("bundled:chute")
    s = problem.solution
    cert = certify(problem, s.v, s.u, s.r, digits=3)
    assert not cert.certified and not cert.reference_ran
    assert "residual" in cert.verdict


def test_nan_solution_is_not_certified():
    problem = rfverify.load("bundled:sphere")
    cert = certify(problem, np.full(problem.n_dofs, np.nan), np.zeros(5), np.zeros(5), digits=1)
    assert not cert.certified


def test_high_precision_residuals_of_exact_reference_are_tiny(chute_ref):
    problem, ref = chute_ref
    res = high_precision_residuals(problem, ref.as_float("v"), ref.as_float("u"), ref.as_float("r"), dps=40)
    assert res["dynamics"] < 1e-14 and res["velocity"] < 1e-14


def test_cli_certify_out_file_rechecks(tmp_path, capsys, chute_ref):
    problem, _ = chute_ref
    sol = tmp_path / "sol.h5"
    assert main(["solve", "bundled:chute", "--out", str(sol)]) == 0
    capsys.readouterr()
    out = tmp_path / "cert.h5"
    code = main(["certify", "bundled:chute", "--solution", str(sol), "--digits", "5", "--json", "--out", str(out)])
    s = json.loads(capsys.readouterr().out)
    assert code == 0 and s["certified"] and s["reference_ran"]
    code10 = main(["certify", "bundled:chute", "--solution", str(sol), "--digits", "10"])
    capsys.readouterr()
    assert code10 == 1
    # The written reference (decimal strings) has tiny residuals of its own, recomputed here
    # at 60 digits, and the claimed digits of v match a recomputation from the file.
    with h5py.File(out, "r") as fh:
        ref_v = [s.decode() if isinstance(s, bytes) else s for s in fh["reference/v"][()]]
        ref_r = [s.decode() if isinstance(s, bytes) else s for s in fh["reference/r"][()]]
        v_dbl = fh["solution/v"][()]
    with mpmath.workdps(60):
        V = [mpmath.mpf(x) for x in ref_v]
        R = [mpmath.mpf(x) for x in ref_r]
        M, H = problem.M_sym.tocoo(), problem.H.tocoo()
        res = [-mpmath.mpf(float(x)) for x in problem.f]
        for i, j, x in zip(M.row, M.col, M.data):
            res[i] += mpmath.mpf(float(x)) * V[j]
        for i, j, x in zip(H.row, H.col, H.data):
            res[i] -= mpmath.mpf(float(x)) * R[j]
        scale = max(abs(mpmath.mpf(float(x))) for x in problem.f)
        assert max(abs(x) for x in res) / scale <= 1e-20
        v_ref = np.array([float(x) for x in V])
    digits_v = -np.log10(np.max(np.abs(v_dbl - v_ref)) / np.max(np.abs(v_ref)))
    assert s["digits"]["v"] == pytest.approx(digits_v, abs=1e-6)


def test_cli_certify_without_solution_is_one_line(tmp_path, capsys):
    code = main(["certify", "bundled:sphere"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "no /solution" in err


@pytest.mark.parametrize("name", ["chute", "cube", "sphere", "sphere-from-global"])
def test_ten_digit_path_is_certified(name):
    from rfverify.refine import solve_to_digits

    problem = rfverify.load(f"bundled:{name}")
    out = solve_to_digits(problem, digits=10)
    assert out.warm.status == "Solved" and "warm start" in out.warm.message
    assert out.certificate.certified, out.certificate.verdict
    # Against the reference the claim is made from, recomputed here: ≥ 10 digits in v.
    ref = out.certificate.reference
    v_ref = ref.as_float("v")
    assert np.max(np.abs(out.v - v_ref)) <= 1e-10 * np.max(np.abs(v_ref))


def test_ten_digit_path_on_generated_problem_with_zero_coefficients():
    from rfverify.random_problems import random_problem
    from rfverify.refine import solve_to_digits

    problem = random_problem(12, 16, seed=5, mu_zero_fraction=0.2, mu_r_zero_fraction=0.3)
    out = solve_to_digits(problem, digits=10)
    assert out.certificate.certified, out.certificate.verdict


def test_cli_solve_digits_then_certify_the_file(tmp_path, capsys):
    sol = tmp_path / "s.h5"
    assert main(["solve", "bundled:cube", "--digits", "10", "--out", str(sol), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["status"] == "Certified" and s["certificate"]["certified"]
    assert main(["certify", "bundled:cube", "--solution", str(sol), "--digits", "10"]) == 0
    assert "certified to 10 digits" in capsys.readouterr().out


def test_public_api_shapes():
    problem = rfverify.load("bundled:sphere")
    result = rfverify.solve(problem, method="jqinv", tol=1e-10)
    cert = rfverify.certify(problem, result, digits=6)
    assert cert.certified and cert.reference_ran
    refined = rfverify.solve_to_digits(problem, digits=10)
    assert refined.success and refined.v.dtype == np.float64


def test_solution_of_another_problem_is_refused(tmp_path, capsys):
    sol = tmp_path / "chute.h5"
    assert main(["solve", "bundled:chute", "--out", str(sol)]) == 0
    capsys.readouterr()
    code = main(["certify", "bundled:cube", "--solution", str(sol)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "different problem" in err
    with pytest.raises(rfverify.InvalidProblemError, match="solution.v"):
        certify(rfverify.load("bundled:cube"), np.zeros(768), None, np.zeros(10))
