"""``--psd-shift`` (:func:`rfverify.shift_to_psd`): a local file whose W is not positive
semidefinite as stored (rounding in Siconos's W = H M⁻¹ Hᵀ) is proven for W + D, D ≥ 0 diagonal,
and every claim names W + D; the physical problem's backward error adds D r*.

The checks here are independent of the library's proof: W + D is compared with the file's W entry
by entry, its smallest eigenvalue is computed in 40-digit mpmath, and the answer's velocity is
recomputed from the file's own W.
"""

from __future__ import annotations

import json
from fractions import Fraction

import mpmath
import numpy as np
import pytest
import scipy.sparse as sp

import rfverify
from rfverify import InvalidArgumentError, InvalidProblemError
from rfverify.cli import main
from test_fclib3d import write_local


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def lambda_min_mp(A, dps=40) -> float:
    with mpmath.workdps(dps):
        S = mpmath.matrix([[(mpmath.mpf(float(A[i, j])) + mpmath.mpf(float(A[j, i]))) / 2 for j in range(A.shape[1])]
                           for i in range(A.shape[0])])
        return float(min(mpmath.eigsy(S)[0]))


def indefinite_local(tmp_path, seed, lam=-1e-14):
    """A 3-D local file (4 contacts) whose W = GᵀG (rank 8 of 12) has one eigenvalue moved to
    ``lam``·‖W‖: the kind of indefiniteness rounding leaves."""
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(8, 12))
    W = G.T @ G
    lam_w, V = np.linalg.eigh(W)
    W = W + (lam * lam_w[-1] - lam_w[0]) * np.outer(V[:, 0], V[:, 0])
    W = 0.5 * (W + W.T)
    q = np.tile([-1.0, 0.3, 0.0], 4)
    return write_local(tmp_path / f"ind{seed}.hdf5", W, q, np.full(4, 0.5)), W


@pytest.mark.parametrize("name", ["bundled:cube", "bundled:sphere-from-global"])
def test_the_shifted_W_is_the_file_s_plus_a_small_nonnegative_diagonal_and_psd(name):
    problem = rfverify.load(name)
    shifted = rfverify.shift_to_psd(problem)
    W, Wp = problem.local.W.toarray(), shifted.local.W.toarray()
    off = ~np.eye(W.shape[0], dtype=bool)
    assert np.array_equal(W[off], Wp[off])
    change = [Fraction(float(b)) - Fraction(float(a)) for a, b in zip(np.diag(W), np.diag(Wp))]
    info = shifted.provenance["psd_shift"]
    assert min(change) >= 0 and max(change) <= Fraction(info["largest_change"]) and max(change) > 0
    assert info["relative"] <= 1e-8
    assert lambda_min_mp(W) < 0 <= lambda_min_mp(Wp)  # the file's W is indefinite, W + D is not
    assert "+ D (D ≥ 0 diagonal" in shifted.statement and "not positive semidefinite" in shifted.statement


def test_a_psd_W_is_left_as_it_is_and_a_global_problem_is_refused():
    sphere = rfverify.load("bundled:sphere")
    assert rfverify.shift_to_psd(sphere) is sphere
    with pytest.raises(InvalidArgumentError, match="applies to a local problem"):
        rfverify.shift_to_psd(rfverify.load("bundled:chute"))


def test_more_than_rounding_is_refused(tmp_path, capsys):
    """A 6-digit print-out is read with an eigenvalue down to −5e-6·‖W‖ (the print's precision);
    one at −1e-6·‖W‖ is no float64 rounding, and no shift up to 1e-8·‖W‖ is accepted for it."""
    from test_local_proof import write_local_dat

    rng = np.random.default_rng(5)
    G = rng.normal(size=(10, 10))
    W = G.T @ G
    lam, V = np.linalg.eigh(W)
    W = W + (-1e-6 * lam[-1] - lam[0]) * np.outer(V[:, 0], V[:, 0])
    path = tmp_path / "printed.dat"
    write_local_dat(path, 0.5 * (W + W.T), np.r_[-1.0, 0, 0, 0, 0, -1.0, 0, 0, 0, 0], [0.5, 0.5], [0.1, 0.1])
    problem = rfverify.load(path)  # read: within the print precision
    with pytest.raises(InvalidProblemError, match="more than rounding"):
        rfverify.shift_to_psd(problem)
    code, out, err = run(capsys, "solve", path, "--psd-shift", "--digits", "10")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and "more than rounding" in err


def test_info_points_to_the_option_only_where_an_eigenvalue_is_negative(capsys):
    code, out, _ = run(capsys, "info", "bundled:cube")
    assert code == 0 and "W may not be positive semidefinite as stored" in out and "--psd-shift" in out
    code, out, _ = run(capsys, "info", "bundled:sphere")
    assert code == 0 and "--psd-shift" not in out


def test_cli_names_the_fix_then_proves_w_plus_d(capsys):
    code, out, _ = run(capsys, "solve", "bundled:cube", "--digits", "10", "--quiet")
    assert code == 1 and "--psd-shift" in out
    code, out, err = run(capsys, "solve", "bundled:cube", "--digits", "10", "--quiet", "--psd-shift", "--json")
    assert code == 0, err
    out = json.loads(out)
    assert out["status"] == "Certified" and "(W + Wᵀ)/2 + D (D ≥ 0 diagonal" in out["message"]
    assert "for W + D as stored (unsymmetric)" in out["message"]  # the stored-equations sentence too


@pytest.mark.parametrize("seed", [2, 3])
def test_answer_of_w_plus_d_solves_the_file_s_w_for_q_plus_d_r(tmp_path, seed):
    """The backward-error reading: (u, r) of W + D is an answer of the file's W for q + D r."""
    path, W = indefinite_local(tmp_path, seed)
    problem = rfverify.load(path)
    shifted = rfverify.shift_to_psd(problem)
    out = rfverify.solve_to_digits(shifted, digits=10)
    assert out.success, out.certificate.verdict
    n = problem.n_contacts
    slots = (5 * np.arange(n)[:, None] + np.arange(3)).ravel()
    r3, u3 = out.r[slots], out.u[slots]
    D = np.diag(shifted.local.W.toarray())[slots] - np.diag(W)
    q = problem.local.q[slots]
    residual = u3 - (W @ r3 + q + D * r3)
    assert np.abs(residual).max() <= 1e-9 * np.abs(q).max()
    # the file's W is singular on the loaded contacts: r* of W + D is unique only through D, so no
    # digits of r are claimed, though it is bounded
    q_r = out.certificate.proof.quantities["r"]
    assert q_r.mode == "information" and np.isfinite(q_r.abs_bound) and "unique only through D" in q_r.note


def test_the_coulomb_backward_error_counts_d_r_and_a_dropped_term_is_caught(monkeypatch):
    shifted = rfverify.shift_to_psd(rfverify.load("bundled:cube"))
    out = rfverify.solve_to_digits(shifted, digits=10, problem="coulomb")
    cert = out.certificate
    assert cert.certified and cert.backward_error <= 1e-10
    be = cert.backward
    r_max = float(np.abs(out.r).max())
    assert be.psd_part >= shifted.provenance["psd_shift"]["largest_change"] * r_max > 0
    assert "D r*" in cert.verdict
    from rfverify.coulomb import api

    monkeypatch.setattr(api, "_psd_terms", lambda *a: {})  # the mutation: D r* left out
    weak = rfverify.solve_to_digits(shifted, digits=10, problem="coulomb").certificate.backward
    assert weak.psd_part == 0 and weak.absolute < be.absolute


def test_bench_loads_every_problem_as_its_options_say_and_keeps_one_choice_per_run(tmp_path, capsys):
    """``bench --psd-shift --max-asymmetry X``: the runs solve W + D (their records' statement
    says so), a global problem in the same run is left as it is, the manifest keeps the choice,
    and the same run directory refuses runs loaded otherwise (exit 2, the fix named)."""
    run = tmp_path / "run"
    common = ["--methods", "jqinv", "--tol", "1e-8", "--digits", "0", "--no-trajectories", "--out", str(run),
              "--quiet"]
    assert main(["bench", "bundled:cube", "bundled:chute", "--psd-shift", "--max-asymmetry", "0.5", *common]) == 0
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["load_options"] == {"psd_shift": True, "max_asymmetry": 0.5}
    records = [json.loads(p.read_text()) for p in (run / "runs").rglob("*.json")]
    statements = {r["problem"]: r["problem_statement"] for r in records}
    cube = next(s for k, s in statements.items() if "cube" in k)
    chute = next(s for k, s in statements.items() if "hute" in k)
    assert "+ D" in cube and "+ D" not in chute
    capsys.readouterr()
    assert main(["bench", "bundled:cube", *common]) == 2
    assert "--psd-shift" in capsys.readouterr().err
