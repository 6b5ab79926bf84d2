"""Certification from the command line and the API: the k-digit path, certificate files that
anyone can recheck, and the second opinion of the reference.  (The soundness of the bound
itself is tested in tests/test_proof.py against an independent 60-digit reference.)"""

from __future__ import annotations

import json

import h5py
import mpmath
import numpy as np
import pytest

import rfverify
from rfverify.model.measures import measures
from rfverify.cli import main
from rfverify.io.certificate import read_point


@pytest.fixture(scope="module")
def chute_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("cert") / "chute10.h5"
    assert main(["solve", "bundled:chute", "--digits", "10", "--out", str(path), "--json"]) == 0
    return path


def test_solve_digits_writes_a_certificate_that_rechecks(chute_file, capsys):
    capsys.readouterr()
    with h5py.File(chute_file, "r") as fh:
        cg = fh["certificate"]
        assert cg.attrs["certified"] and cg.attrs["requested_digits"] == 10
        assert "monotonicity" in cg.attrs["theorem"]
        assert cg.attrs["problem"] == "the convex relaxation with (M + Mᵀ)/2" and cg.attrs["equations"] == "symmetrised"
        v_dec = [s.decode() if isinstance(s, bytes) else s for s in cg["point/v_decimal"][()]]
        v_sol = fh["solution/v"][()]
        eps = cg["terms"].attrs["eps_M"]
        bound_v = cg["quantities/v"].attrs["abs_bound"]
    # The decimal strings are the exact point to 34 digits; the stored solution is its rounding.
    with mpmath.workdps(40):
        dev = max(abs(mpmath.mpf(s) - mpmath.mpf(float(x))) for s, x in zip(v_dec, v_sol))
    assert float(dev) <= 1e-16 * np.max(np.abs(v_sol)) and eps > 0 and bound_v > 0
    code = main(["certify", "bundled:chute", "--solution", str(chute_file), "--digits", "10", "--json"])
    s = json.loads(capsys.readouterr().out)
    assert code == 0 and s["certified"] and s["quantities"]["v"]["abs_bound"] == bound_v


def test_recheck_from_the_file_alone_is_exact_and_cheap(chute_file):
    problem = rfverify.load("bundled:chute")
    stored = rfverify.load(chute_file).solution
    point = read_point(chute_file)
    cert = rfverify.certify(problem, stored, digits=10, point=point)
    assert cert.certified and cert.extra["point_source"] == "given"
    assert cert.seconds < 5.0  # O(nnz) exact arithmetic, no solve


def test_tampered_solution_in_the_file_is_caught(chute_file, tmp_path, capsys):
    bad = tmp_path / "tampered.h5"
    bad.write_bytes(chute_file.read_bytes())
    with h5py.File(bad, "a") as fh:
        v = fh["solution/v"][()]
        k = int(np.argmax(np.abs(v)))
        v[k] *= 1 + 1e-8  # the 9th digit of the largest entry
        fh["solution/v"][...] = v
    capsys.readouterr()
    assert main(["certify", "bundled:chute", "--solution", str(bad), "--digits", "10"]) == 1
    out = capsys.readouterr().out
    assert "not proven to 10 digits" in out and "v has" in out


@pytest.mark.parametrize("key", ["v_decimal", "r_decimal"])
def test_tampered_decimal_strings_are_refused(chute_file, tmp_path, capsys, key):
    """The decimal strings must denote the binary point the proof is about: one changed digit
    is refused (exit 2, one line naming the dataset and the index); the same number written
    differently is not a disagreement."""
    bad = tmp_path / "tampered.h5"
    bad.write_bytes(chute_file.read_bytes())
    with h5py.File(bad, "a") as fh:
        ds = fh[f"certificate/point/{key}"]
        strings = [x.decode() if isinstance(x, bytes) else x for x in ds[()]]
        k = max(range(len(strings)), key=lambda j: abs(float(strings[j])))  # a non-zero entry
        digit = strings[k].lstrip("-")[0]
        ds[k] = strings[k].replace(digit, "1" if digit != "1" else "2", 1)
    capsys.readouterr()
    assert main(["certify", "bundled:chute", "--solution", str(bad)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and err.startswith("rfverify certify: error: "), err
    for text in (str(bad), f"/certificate/point/{key}", f"{key}[{k}]", strings[k], "fix:"):
        assert text in err, (text, err)
    with h5py.File(bad, "a") as fh:  # the same number, spelt with an exponent: accepted
        fh[f"certificate/point/{key}"][k] = strings[k] + "e0"
    assert main(["certify", "bundled:chute", "--solution", str(bad)]) == 0
    capsys.readouterr()
    assert main(["certify", "bundled:chute", "--solution", str(chute_file)]) == 0


def test_double_solution_gets_its_proven_digits(tmp_path, capsys):
    sol = tmp_path / "d.h5"
    assert main(["solve", "bundled:chute", "--out", str(sol)]) == 0
    capsys.readouterr()
    assert main(["certify", "bundled:chute", "--solution", str(sol), "--digits", "10"]) == 1
    capsys.readouterr()
    code = main(["certify", "bundled:chute", "--solution", str(sol), "--digits", "5", "--json"])
    s = json.loads(capsys.readouterr().out)
    assert code == 0 and 5 <= s["quantities"]["v"]["digits"] < 10


def test_cross_check_reports_agreement_with_the_reference(capsys, tmp_path):
    """A local problem's cross-check runs the reference on the file's own W (not the lifting)."""
    sol = tmp_path / "diag.h5"
    src = tmp_path / "diag.dat"
    src.write_text(_local_dat([1, 1, 1e-6, 1, 1], [-1, 0, 1e-3, 0, 0], 0.5, 0.1))
    assert main(["solve", str(src), "--digits", "10", "--out", str(sol)]) == 0
    capsys.readouterr()
    code = main(["certify", str(src), "--solution", str(sol), "--cross-check", "--dps", "40", "--json"])
    s = json.loads(capsys.readouterr().out)
    cc = s["cross_check"]
    assert code == 0 and cc["reference_status"] == "Solved" and set(s["quantities"]) == {"u", "r"}
    # agreement with the independent reference is at least the proven digits (up to rounding)
    assert cc["digits_u"] >= s["quantities"]["u"]["digits"] - 0.3
    assert cc["digits_r"] >= s["quantities"]["r"]["digits"] - 0.3


def test_local_file_with_an_indefinite_W_is_not_certified(capsys):
    """The bundled cube's W is rank 6 of 10, and its printed rounding is indefinite (exact
    rational LDLᵀ): its local problem is not convex, so nothing is certified about it."""
    code = main(["solve", "bundled:cube", "--digits", "10"])
    out = capsys.readouterr().out
    assert code == 1 and "not positive semidefinite" in out and "proven" not in out.split("\n")[1]


def _local_dat(diag, q, mu, mu_r) -> str:
    n5 = len(diag)
    rows = "\n".join(" ".join(repr(float(diag[i])) if i == j else "0" for j in range(n5)) for i in range(n5))
    return (f"5\n{n5 // 5}\n0\n{n5}\n{n5}\n{n5}\t{n5}\n{rows}\n" + " ".join(repr(float(x)) for x in q)
            + f"\n{mu!r}\n{mu_r!r}\n")


def test_certify_out_writes_point_and_bound(tmp_path, capsys):
    sol = tmp_path / "s.h5"
    out = tmp_path / "cert.h5"
    assert main(["solve", "bundled:sphere", "--out", str(sol)]) == 0
    assert main(["certify", "bundled:sphere", "--solution", str(sol), "--digits", "6", "--out", str(out),
                 "--quiet"]) == 0
    capsys.readouterr()
    point = read_point(out)
    assert point is not None and point.v_hi.size == rfverify.load("bundled:sphere").n_dofs
    # the written file certifies itself again from its own point
    assert main(["certify", "bundled:sphere", "--solution", str(out), "--digits", "6"]) == 0


@pytest.mark.parametrize("bad", ["0", "-5", "2.5", "16", "18", "ten"])
def test_cli_digits_out_of_range_is_exit_2(bad, capsys):
    with pytest.raises(SystemExit) as stop:
        main(["solve", "bundled:sphere", "--digits", bad])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "fix:" in err


def test_cli_certify_without_solution_is_one_line(capsys):
    code = main(["certify", "bundled:sphere"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "no /solution" in err


def test_solution_of_another_problem_is_refused(tmp_path, capsys):
    sol = tmp_path / "chute.h5"
    assert main(["solve", "bundled:chute", "--out", str(sol)]) == 0
    capsys.readouterr()
    code = main(["certify", "bundled:cube", "--solution", str(sol)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "different problem" in err
    with pytest.raises(rfverify.InvalidProblemError, match="solution.v"):
        rfverify.certify(rfverify.load("bundled:cube"), np.zeros(768), None, np.zeros(10))


def test_nan_solution_is_not_certified():
    problem = rfverify.load("bundled:sphere")
    cert = rfverify.certify(problem, np.full(problem.n_dofs, np.nan), None, np.zeros(5 * problem.n_contacts),
                            digits=1)
    assert not cert.certified and "NaN" in cert.verdict


def test_stored_zero_solution_is_not_certified():
    """The Chute file stores v = 0 and r = 0: the proof gives it no digits."""
    problem = rfverify.load("bundled:chute")
    cert = rfverify.certify(problem, problem.solution, digits=3)
    assert not cert.certified


def test_public_api_shapes():
    problem = rfverify.load("bundled:sphere")
    result = rfverify.solve(problem, method="jqinv", tol=1e-10)
    cert = rfverify.certify(problem, result, digits=6)
    assert cert.certified and set(cert.digits) == {"u", "r"}  # a local file: its own quantities
    glob = rfverify.load("bundled:chute")
    cert = rfverify.certify(glob, rfverify.solve(glob, tol=1e-10), digits=5)
    assert cert.certified and set(cert.digits) == {"v", "u", "Hr", "r"}
    ten = rfverify.solve_to_digits(problem, digits=10)
    assert ten.success and ten.v.dtype == np.float64 and ten.point is not None
    assert set(ten.timings) >= {"double", "extended", "proof", "total"}


def test_the_criterion_at_40_digits_of_a_ten_digit_solution_is_tiny():
    problem = rfverify.load("bundled:chute")
    ten = rfverify.solve_to_digits(problem, digits=10)
    res = measures(problem, ten.v, ten.u, ten.r, 40)
    assert res.dynamics < 1e-14 and res.velocity < 1e-14


def test_the_k_digit_path_continues_a_centred_double_solve(monkeypatch):
    """The double solve that the k-digit path and certify's polishing continue uses
    digits.DOUBLE_SETTINGS (the paper's centring rule: measured, from the default hybrid
    rule's iterate the Lattice 474's double-double phase stalled 22 orders of μ earlier); a
    caller's own option still wins."""
    from rfverify import solver
    from rfverify.verify import certification, digits

    seen = {"digits": [], "certify": []}
    real = solver.solve

    def recording(path):
        def solve(problem, *args, **kwargs):
            seen[path].append(kwargs.get("sigma_rule"))
            return real(problem, *args, **kwargs)
        return solve

    problem = rfverify.load("bundled:chute")
    assert digits.DOUBLE_SETTINGS["sigma_rule"] == "paper"
    monkeypatch.setattr(digits, "solve", recording("digits"))
    assert rfverify.solve_to_digits(problem, digits=10).certificate.certified
    assert rfverify.solve_to_digits(problem, digits=10, sigma_rule="hybrid").certificate.certified
    assert seen["digits"] == ["paper", "hybrid"]
    res = real(problem)
    monkeypatch.setattr(solver, "solve", recording("certify"))  # certify imports it when called
    cert = certification.certify(problem, res.v, res.u, res.r, digits=10)
    # (a double candidate is not 10 digits accurate, so it is not certified; the path is what counts)
    assert seen["certify"][:1] == ["paper"] and not cert.certified


def test_a_given_proof_point_that_fails_is_a_hint_not_the_last_word(tmp_path, capsys):
    """A global lifting written from the bundled local sphere keeps the local certificate, whose
    point is another problem's: tried first, it fails (u ∉ K*), and the solution is then proven
    from the candidate and a computed point (it stopped at 'not certified' before)."""
    from rfverify.cli import main

    path = tmp_path / "sphere_lifted.h5"
    assert main(["solve", "bundled:sphere", "--digits", "10", "--out", str(path), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["certify", str(path)]) == 0
    out, err = capsys.readouterr()
    assert out.startswith("certified") and "the stored point gives no proof" in err
    assert "about ANOTHER problem" in out  # the stored claim is still judged as what it is


def test_cross_check_of_a_zero_quantity_is_measured_at_its_data_scale():
    """Audit (2026-12-08): the sphere at rest has u* = 0; the reference's u (≈1e-42) and the
    answer's (≈1e-19) were compared relative to each other: 'agreement u -22.7', read as a huge
    disagreement next to a certificate 'u zero within 1.8e-19'.  Agreement is now relative to
    the larger of the exact size and the data scale, as the certificate's absolute bounds are."""
    p = rfverify.load("bundled:sphere")
    ten = rfverify.solve_to_digits(p, digits=10)
    cert = rfverify.certify(p, ten, digits=10, cross_check=True)
    assert cert.certified
    agree = cert.cross_check
    assert agree["digits_u"] >= 10 and agree["digits_r"] >= 10, agree


def test_certifying_a_physical_answer_as_the_relaxations_points_to_problem_coulomb(tmp_path, capsys):
    """Audit (2026-12-08): a file written by `solve --problem coulomb` certified without
    --problem coulomb printed 'not proven … u has no relative digits' and nothing else; the file
    says what it holds (/coulomb/shift), and the output now says so, with the fix."""
    from rfverify.cli import main

    sol = tmp_path / "coulomb.h5"
    assert main(["solve", "bundled:chute", "--problem", "coulomb", "--out", str(sol), "--quiet"]) == 0
    capsys.readouterr()
    main(["certify", "bundled:chute", "--solution", str(sol)])
    assert "certify it with --problem coulomb" in capsys.readouterr().out
    main(["certify", "bundled:chute", "--solution", str(sol), "--json"])
    assert "--problem coulomb" in json.loads(capsys.readouterr().out)["note"]


def test_a_search_that_stalls_says_why():
    """Audit (2026-12-08): a k-digit run whose double-double steps stayed near 1e-6 ended 'not
    proven … Hr 0.6 digits' with no reason; the JSON's extended status 'Stopped' reads like a
    user's interrupt.  Where the search for a proof point stops because μ no longer falls, the
    verdict says so, at which iteration, and which cone held the last step."""
    from pathlib import Path

    from rfverify.proof.bound import invalid_proof
    from rfverify.verify.certificate import certificate_from_proof

    words = "the search stopped at iteration 4: μ = 1e-12 had not halved in 4 iterations"
    failed = certificate_from_proof(invalid_proof(10, "the point is not in the cones", 0.0),
                                    extra={"search_stopped": words})
    assert failed.verdict.endswith(f"({words})")
    p = rfverify.load(str(Path(__file__).parent / "data" / "hard" / "SpheresPile-f2e-20-ndof-120-nc-37-0.hdf5"))
    res = rfverify.solve_to_digits(p, 10)
    assert res.certificate.certified or ("the search stopped at iteration" in res.message
                                         and "held by contact" in res.message), res.message


def test_a_stalled_search_starts_again_from_another_double_answer():
    """Fresh-data audit (2026-12-08): from auto's double answer (jqinv) the search for a proof
    point stalls at steps of 1e-6 and proves nothing; from noscaling's it proves 10 digits.  The
    path now starts again from there, says so, and counts the first start's time.  A form the
    caller chose is kept: then no second start."""
    from pathlib import Path

    p = rfverify.load(str(Path(__file__).parent / "data" / "hard" / "MassRatio-1e16-ndof-120-nc-39-0.hdf5"))
    res = rfverify.solve_to_digits(p, 10)
    assert res.certificate.certified, res.message
    assert res.double.method == "noscaling" and "found from the noscaling double answer" in res.message
    assert "the search stopped at iteration" in res.certificate.extra["second_start"]
    assert 0 < res.timings["first_start"] < res.timings["total"]
    chosen = rfverify.solve_to_digits(p, 10, method="jqinv")
    assert not chosen.certificate.certified and "second_start" not in chosen.certificate.extra
