"""Issue 51: the physical problem (Coulomb friction and rolling resistance with De Saxcé's term),
solved as a fixed point of shifted convex solves and certified by a proven backward error.

The recheck here is independent of rfverify's measures: the written (v, r) is read back from the
file with h5py and judged against the physical conditions in mpmath (40 digits), from the
problem's raw data.  The bound on δ is checked against a closed-form exact answer."""

from __future__ import annotations

import json
import math
from fractions import Fraction

import h5py
import mpmath
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import example, given, settings, strategies as st

import rfverify
from rfverify.cli import main
from rfverify.coulomb import backward, certify_coulomb, model, solve_coulomb


# ---------------------------------------------------------------- the independent recheck
def physical_violations(problem, v, r, dps: int = 40) -> dict:
    """The physical conditions at (v, r) in mpmath, each relative to a scale of its terms:
    dynamics ‖(M+Mᵀ)/2 v − H r − f‖∞ / (‖|M||v|‖∞ + ‖|H||r|‖∞ + ‖f‖∞); with u = Hᵀv + w and
    ũ = u + (μ‖u_T‖ + μr‖u_R‖)e_N: max(−u_N)⁺ / ‖u‖∞, cone max(‖r_T‖ − μr_N, ‖r_R‖ − μr r_N)⁺ / ‖r‖∞,
    and max_i |r_iᵀũ_i| / (‖r‖∞‖ũ‖∞)."""
    with mpmath.workdps(dps):
        mpf = mpmath.mpf
        m, n = problem.n_dofs, problem.n_contacts
        vv = [mpf(float(x)) for x in v]
        rr = [mpf(float(x)) for x in r]
        Mc = sp.coo_matrix(problem.M)
        Mv = [mpf(0)] * m
        Mabs = [mpf(0)] * m
        for i, j, x in zip(Mc.row, Mc.col, Mc.data):  # (M + Mᵀ)/2 v, from the raw stored M
            h = mpf(float(x)) / 2
            Mv[i] += h * vv[j]
            Mv[j] += h * vv[i]
            Mabs[i] += abs(h * vv[j])
            Mabs[j] += abs(h * vv[i])
        Hc = sp.coo_matrix(problem.H)
        Hr = [mpf(0)] * m
        Habs = [mpf(0)] * m
        u = [mpf(float(x)) for x in problem.w]
        for i, j, x in zip(Hc.row, Hc.col, Hc.data):
            Hr[i] += mpf(float(x)) * rr[j]
            Habs[i] += abs(mpf(float(x)) * rr[j])
            u[j] += mpf(float(x)) * vv[i]
        f = [mpf(float(x)) for x in problem.f]
        dyn = max(abs(Mv[i] - Hr[i] - f[i]) for i in range(m))
        dyn_scale = max(Mabs) + max(Habs) + max(abs(x) for x in f)
        out = {"dynamics": float(dyn / dyn_scale)}
        u_inf = max(abs(x) for x in u)
        r_inf = max(abs(x) for x in rr) or mpf(1)
        normal = cone = comp = mpf(0)
        ut_inf = mpf(0)
        tilde = []
        for i in range(n):
            ui, ri = u[5 * i:5 * i + 5], rr[5 * i:5 * i + 5]
            mu, mur = mpf(float(problem.mu[i])), mpf(float(problem.mu_r[i]))
            phi = mu * mpmath.sqrt(ui[1] ** 2 + ui[2] ** 2) + mur * mpmath.sqrt(ui[3] ** 2 + ui[4] ** 2)
            t = [ui[0] + phi] + ui[1:]
            tilde.append((t, ri))
            ut_inf = max(ut_inf, max(abs(x) for x in t))
            normal = max(normal, -ui[0])
            cone = max(cone, mpmath.sqrt(ri[1] ** 2 + ri[2] ** 2) - mu * ri[0],
                       mpmath.sqrt(ri[3] ** 2 + ri[4] ** 2) - mur * ri[0])
        for t, ri in tilde:
            comp = max(comp, abs(sum(a * b for a, b in zip(t, ri))))
        out["normal"] = float(normal / u_inf) if u_inf else float(normal)
        out["cone"] = float(cone / r_inf)
        out["complementarity"] = float(comp / (r_inf * ut_inf)) if ut_inf else 0.0
        return out


def read_solution(path):
    with h5py.File(path, "r") as fh:
        return fh["solution/v"][()], fh["solution/r"][()]


@pytest.fixture(scope="module")
def chute():
    return rfverify.load("bundled:chute")


@pytest.fixture(scope="module")
def chute_written(tmp_path_factory):
    """``rfverify solve bundled:chute --problem coulomb --digits 10 --out SOL --json``: (exit code,
    JSON, SOL path) — the issue's done-when command."""
    path = tmp_path_factory.mktemp("coulomb") / "sol.h5"
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["solve", "bundled:chute", "--problem", "coulomb", "--digits", "10", "--out", str(path),
                     "--json", "--quiet"])
    return code, json.loads(buf.getvalue()), path


def test_chute_is_proven_with_backward_error_below_1e_10(chute_written):
    code, out, _ = chute_written
    assert code == 0
    assert out["problem"] == "coulomb" and out["status"] == "Certified"
    assert out["backward_error"] <= 1e-10
    assert "need not be unique" in out["verdict"] and "backward-error certificate" in out["verdict"]
    # the chute's M is unsymmetric (in blocks no contact touches): the verdict names the equations proven
    assert "physical problem (Coulomb" in out["verdict"] and ") with (M + Mᵀ)/2 for data" in out["verdict"]
    # the physical u's bound contains the inner proof's (u* = u'* − ŝ e_N: the same distance, and more)
    assert out["quantities"]["u"]["abs_bound"] >= out["inner_certificate"]["quantities"]["u"]["abs_bound"] > 0


def test_written_chute_answer_satisfies_the_physical_conditions_independently(chute, chute_written):
    _, _, path = chute_written
    v, r = read_solution(path)
    bad = physical_violations(chute, v, r)
    assert all(x <= 1e-10 for x in bad.values()), bad


def test_the_relaxation_answer_fails_the_same_recheck(chute):
    """The recheck can fail: the relaxation's answer (the shift dropped) separates at the
    sliding speed, and its complementarity of rᵀũ is 0.2 of the scale."""
    res = rfverify.solve(chute)
    bad = physical_violations(chute, res.v, res.r)
    assert bad["complementarity"] > 1e-3, bad


def test_certify_rechecks_the_written_file_with_its_shift(chute_written, capsys):
    _, _, path = chute_written
    code = main(["certify", "bundled:chute", "--solution", str(path), "--problem", "coulomb", "--json", "--quiet"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["backward_error"] <= 1e-10 and out["problem"] == "coulomb"


def test_dropping_the_shift_is_caught(chute, monkeypatch):
    """Mutation: the shifted problem without its shift (the relaxation solved every time).  The
    backward error then measures Φ(u) itself, and nothing is certified."""
    monkeypatch.setattr(model.dataclasses, "replace", _keep_w(model.dataclasses.replace))
    out = rfverify.solve_to_digits(chute, digits=6, problem="coulomb", proven_rounds=1, outer_max_iter=3)
    assert not out.success and out.backward_error > 1e-3


def _keep_w(replace):
    def mutated(obj, **changes):
        changes.pop("w", None)
        return replace(obj, **changes)
    return mutated


def test_relaxation_stays_the_default_bit_for_bit(chute):
    a, b = rfverify.solve(chute), rfverify.solve(chute, problem="relaxation")
    for name in ("v", "u", "r"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.status == b.status and a.nit == b.nit
    with pytest.raises(rfverify.InvalidArgumentError, match="problem"):
        rfverify.solve(chute, problem="physical")


# ---------------------------------------------------------------- one sliding block, in closed form
def block(mu: float, fT=(1.2, 1.6), fN: float = -1.0):
    """One body (M = I, 3 dofs = the contact's N, T1, T2 velocities) pushed into the ground with
    |f_N| and along it with f_T: u = v, and where ‖f_T‖ > μ|f_N| it slides.  Physical solution:
    r_N = |f_N|, u_N = 0, u_T = f_T (1 − μ|f_N|/‖f_T‖)."""
    H = np.zeros((3, 5))
    H[:, :3] = np.eye(3)
    return rfverify.Problem.from_arrays(np.eye(3), H, [fN, *fT], np.zeros(5), [mu], [0.0])


def exact_delta(problem, s_hat: float) -> float:
    """δ = ŝ − μ‖u*_T‖ for the exact solution of the convex problem with w_N = ŝ (sliding):
    r_N = (|f_N| + μF − ŝ)/(1 + μ²), ‖u*_T‖ = F − μ r_N, F = ‖f_T‖ (mpmath, 60 digits)."""
    with mpmath.workdps(60):
        mu = mpmath.mpf(float(problem.mu[0]))
        F = mpmath.sqrt(mpmath.mpf(float(problem.f[1])) ** 2 + mpmath.mpf(float(problem.f[2])) ** 2)
        fN = -mpmath.mpf(float(problem.f[0]))
        s = mpmath.mpf(Fraction(s_hat).numerator) / Fraction(s_hat).denominator
        rN = (fN + mu * F - s) / (1 + mu * mu)
        return float(s - mu * (F - mu * rN))


def test_sliding_block_physical_answer_is_the_closed_form():
    p = block(0.5)
    out = solve_coulomb(p)
    assert out.success
    np.testing.assert_allclose(out.r[:3], [1.0, -0.5 * 0.6, -0.5 * 0.8], atol=1e-11)
    np.testing.assert_allclose(out.u[:3], [0.0, 1.2 * 0.75, 1.6 * 0.75], atol=1e-11)
    relax = rfverify.solve(p)
    assert relax.u[0] > 0.1  # the relaxation separates at the sliding speed


@pytest.mark.parametrize("offset", [0.0, 1e-5])
def test_delta_bound_holds_and_is_tight_on_a_perturbed_candidate(offset):
    """A candidate off the solution by 1e-6 along u_T (both components): the bound must cover the
    exact δ (so dropping the √2·μ·e_u term, the √2, or the |ŝ − Φ(û)| term is caught) and stay
    within a small factor of it (so an inflated bound is caught too)."""
    p = block(0.5)
    v = np.array([0.0, 0.9 + 0.6e-6, 1.2 + 0.8e-6])
    r = np.array([1.0, -0.3, -0.4, 0.0, 0.0])
    s_hat = float(model.phi(p, np.r_[v, 0.0, 0.0])[0]) + offset
    cert = certify_coulomb(p, v, None, r, digits=9, shift=[s_hat])
    true = abs(exact_delta(p, s_hat))
    bound = float(cert.backward.delta[0])
    assert cert.backward.proven
    assert bound >= true, (bound, true)
    assert bound <= 3 * true + 1e-15, (bound, true)


@pytest.mark.parametrize("mutation", ["no_sqrt2", "no_lipschitz", "no_fixed_point"])
def test_weakened_delta_bounds_are_caught(mutation, monkeypatch):
    """The same check with the bound weakened three ways: each must fail it."""
    if mutation == "no_sqrt2":
        monkeypatch.setattr(backward, "SQRT2_UP", 1.0)
    elif mutation == "no_lipschitz":
        monkeypatch.setattr(backward, "SQRT2_UP", 0.0)
    else:
        original = backward.phi_bounds
        monkeypatch.setattr(backward, "phi_bounds", lambda problem, u: _shifted_bounds(problem, original(problem, u)))
    p = block(0.5)
    v = np.array([0.0, 0.9 + 0.6e-6, 1.2 + 0.8e-6])
    r = np.array([1.0, -0.3, -0.4, 0.0, 0.0])
    offset = 1e-5 if mutation == "no_fixed_point" else 0.0
    s_hat = float(model.phi(p, np.r_[v, 0.0, 0.0])[0]) + offset
    cert = certify_coulomb(p, v, None, r, digits=9, shift=[s_hat])
    assert float(cert.backward.delta[0]) < abs(exact_delta(p, s_hat))


def _shifted_bounds(problem, bounds):
    """Φ's bounds moved onto the applied shift: the |ŝ − Φ(û)| term then vanishes."""
    lo, hi = bounds
    return lo + 1e-5, hi + 1e-5


@settings(max_examples=8)
@given(mu=st.floats(0.1, 1.5), push=st.floats(1.2, 3.0), load=st.floats(0.5, 2.0))
@example(mu=0.1015625, push=1.203125, load=1.5)  # slow sliding: u_N = −2.6e-12 against ‖u‖∞ = 0.025
def test_sliding_blocks_solve_and_certify(mu, push, load):
    """Random sliding blocks (‖f_T‖ = push·μ·|f_N|): the proven answer is the closed form, and
    its backward error is below 1e-10.  The physical conditions hold to 1e-10 of their scales,
    u_N ≥ 0 and r ⊥ ũ up to what the certificate allows: it proves the exact solution for w_N
    moved by δ (|δ| ≤ backward error × ‖f‖∞ here), within u's proven bound of the answer, and
    where the block slides slowly ‖u‖∞ is small beside those."""
    F = push * mu * load
    p = block(mu, fT=(0.6 * F, 0.8 * F), fN=-load)
    out = rfverify.solve_to_digits(p, digits=10, problem="coulomb")
    assert out.success and out.backward_error <= 1e-10
    assert abs(out.r[0] - load) <= 1e-9 * load
    assert abs(out.u[0]) <= 1e-9 * F
    bad = physical_violations(p, out.v, out.r)
    u_inf = float(np.max(np.abs(p.H.T @ out.v + p.w)))
    allowed = (out.backward_error * float(np.max(np.abs(p.f))) + out.certificate.quantities["u"].abs_bound) / u_inf
    assert bad["dynamics"] <= 1e-10 and bad["cone"] <= 1e-10, bad
    assert bad["normal"] <= 1e-10 + allowed and bad["complementarity"] <= 1e-10 + allowed, (bad, allowed)


def test_non_convergence_is_reported_with_its_residual(chute):
    out = solve_coulomb(chute, outer_max_iter=2)
    assert not out.success and str(out.status) == "MaxIterations"
    assert "fixed-point residual" in out.message and math.isfinite(out.outer.residual)


def test_cli_help_names_the_problem_option(capsys):
    for command in ("solve", "certify"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        assert "--problem {relaxation,coulomb}" in capsys.readouterr().out


def test_a_start_at_the_fixed_point_needs_one_evaluation(chute):
    """``start`` is used: from the shift of a converged answer (an array, or the result itself),
    the outer iteration is at its fixed point on its first evaluation, where from 0 it takes
    many; the JSON and the result say where it started."""
    first = solve_coulomb(chute)
    assert first.success and first.outer.evaluations > 3 and not first.outer.started
    for start in (first.shift, first):
        again = rfverify.solve(chute, problem="coulomb", start=start)
        assert again.success and again.outer.evaluations == 1 and again.outer.started
        assert again.as_dict()["outer"]["start"] == "given shift"
    assert first.as_dict()["outer"]["start"] == "zero"


@pytest.mark.parametrize("bad, words", [(np.zeros(3), "needs 4 finite entries"),
                                        (np.array([0.0, np.nan, 0.0, 0.0]), "with NaN or Inf"),
                                        (np.array([0.0, -1e-3, 0.0, 0.0]), "negative shift on contact 1")])
def test_a_bad_start_is_refused_by_name(chute, bad, words):
    with pytest.raises(rfverify.InvalidArgumentError, match=words) as err:
        rfverify.solve(chute, problem="coulomb", start=bad)
    assert err.value.argument == "start"


def test_cli_start_from_a_solution_file(chute_written, tmp_path, capsys):
    """``solve --problem coulomb --start SOL.h5``: the shift stored with the answer (far fewer
    evaluations, proven again; one without --digits, whose fixed point is the double one); a file of another problem, one without a /solution, and --start
    without --problem coulomb are one line and exit 2."""
    _, first, path = chute_written
    code = main(["solve", "bundled:chute", "--problem", "coulomb", "--digits", "10", "--start", str(path),
                 "--json", "--quiet"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["status"] == "Certified" and out["backward_error"] <= 1e-10
    # the stored shift is the proven answer's: the double fixed point is a few 1e-9 away from it
    assert out["outer"]["start"] == "given shift" and first["outer"]["start"] == "zero"
    assert out["outer"]["evaluations"] < first["outer"]["evaluations"] / 2, (out["outer"], first["outer"])
    code = main(["solve", "bundled:chute", "--problem", "coulomb", "--start", str(path), "--quiet"])
    assert code == 0 and "from the --start shift" in capsys.readouterr().out
    bare = tmp_path / "bare.h5"
    import dataclasses

    rfverify.save(dataclasses.replace(rfverify.load("bundled:chute"), solution=None), bare)
    for argv, words in ((["--problem", "coulomb", "--start", str(bare)], "has no /solution"),
                        (["--start", str(path)], "--start: is for the physical problem only"),
                        (["--problem", "coulomb", "--start", "bundled:sphere"], "holds a different problem")):
        code = main(["solve", "bundled:chute", *argv, "--quiet"])
        err = capsys.readouterr().err.strip()
        assert code == 2 and len(err.splitlines()) == 1 and words in err, err


HARD = __import__("pathlib").Path(__file__).parent / "data" / "hard"


@pytest.fixture(scope="module")
def chute181():
    return rfverify.load(str(HARD / "Chute-ndof-900-nc-181-1-3d.hdf5"))


def test_friction_continuation_finds_the_fixed_point_the_iteration_from_zero_misses(chute181):
    """From s = 0 the 181-contact Chute's iteration lands where a sliding contact's Φ grows faster
    than its shift (no fixed point there) and stalls; walking μ up from the frictionless problem
    reaches one.  Its answer meets the physical conditions in an mp recheck."""
    alone = solve_coulomb(chute181, continuation=False)
    assert not alone.success and alone.outer.residual > 1e-6 and not alone.outer.stages
    out = solve_coulomb(chute181)
    assert out.success and out.outer.residual <= 1e-11, out.message
    stages = out.outer.stages
    assert stages[0]["friction"] == 1.0 and not stages[0]["converged"]
    assert stages[-1]["friction"] == 1.0 and stages[-1]["converged"]
    assert all(0 < st["friction"] < 1 and st["converged"] for st in stages[1:-1]) and len(stages) > 2
    assert out.outer.total_evaluations == sum(st["evaluations"] for st in stages) > out.outer.evaluations
    assert "friction continuation" in out.message
    d = out.as_dict()["outer"]
    assert d["total_evaluations"] == out.outer.total_evaluations and len(d["stages"]) == len(stages)
    bad = physical_violations(chute181, out.v, out.r, dps=30)
    assert all(x <= 1e-9 for x in bad.values()), bad


def test_friction_scaled_changes_mu_and_mu_r_only(chute):
    half = model.friction_scaled(chute, 0.5)
    assert np.array_equal(half.mu, chute.mu * 0.5) and np.array_equal(half.mu_r, chute.mu_r * 0.5)
    assert half.w is chute.w and half.f is chute.f and half.M is chute.M and half.H is chute.H
    assert model.friction_scaled(chute, 1.0) is chute


def test_the_proven_rounds_wait_for_a_slow_secant_model():
    """The 101-contact MassRatio's proven rounds fall slowly at first (1.9e-8, 1.1e-9, 9.5e-10,
    1.1e-9, 8.8e-10, then 2.5e-10 …): they are certified below 1e-10, and its written answer
    rechecks."""
    problem = rfverify.load(str(HARD / "MassRatio-ndof-240-nc-101-1-3d.hdf5"))
    out = rfverify.solve_to_digits(problem, 10, problem="coulomb")
    assert out.certificate.certified and out.backward_error <= 1e-10, out.certificate.verdict
    assert len(out.rounds) > 5
    bad = physical_violations(problem, out.v, out.r, dps=30)
    assert all(x <= 1e-10 for x in bad.values()), bad


def test_an_inner_solver_that_refuses_the_problem_is_not_a_fixed_point(chute):
    """An inner solve with status InvalidInput (e.g. Siconos's GRFC3D on a 3-D file) has no u to
    iterate on: the run says so and its status is InvalidInput, never a residual of 0."""
    from rfverify.coulomb.outer import find_shift
    from rfverify.solver.result import Status

    class Refused:
        status, message, nit, u = Status.INVALID_INPUT, "this solver takes no such problem", 0, None

    run = find_shift(chute, evaluate=lambda shifted: (Refused(), np.zeros(5 * chute.n_contacts)))
    assert run.refused and run.inner is None and not run.converged and run.residual == math.inf
    assert "refused the shifted problem: this solver takes no such problem" in run.message and not run.stages


@pytest.mark.parametrize("u_normal, u_tangent, zeroed", [(1e-3, 0.0, True), (2.0 ** -20 - 1e-12, 0.0, False),
                                                         (5e-4, 0.0, True), (1e-3, 1.0, False)])
def test_a_contact_proven_open_and_apart_carries_no_backward_error(chute, u_normal, u_tangent, zeroed):
    """δ_i = 0 only where û_i ± e_u lies in int K*_i (so r*_i = 0) and the physical u*_N =
    u'*_N − ŝ_i ≥ 0 is proven: with ŝ_0 = 2⁻²⁰ and e_u = 1e-12, û_N = 2⁻²⁰ − 1e-12 leaves the
    physical normal velocity possibly negative (not zeroed), 5e-4 and 1e-3 do not; with u_T = 1
    the box is not inside K*_0 (r*_0 may be loaded: not zeroed).  The fixed point there is far
    off (|Φ_0 − ŝ_0| ≥ 1e-6), so a zeroed δ_0 is visible."""
    n = chute.n_contacts
    s = np.zeros(n)
    s[0] = 2.0 ** -20
    shifted = model.shifted_problem(chute, s)
    u = np.zeros(5 * n)
    u[0::5] = 1.0  # every contact far inside K*: open, its physical u_N = 1 − ŝ ≥ 0
    u[0], u[1] = u_normal, u_tangent  # contact 0 (u_T = 0: Φ_0(û) = 0 and |ŝ_0 − Φ_0| = 2⁻²⁰)
    be = backward.backward_bound(chute, shifted, u, 1e-12, 1.0, "scale")
    assert be.delta[1:].max() == 0 and be.open_contacts == n - 1 + zeroed
    assert (be.delta[0] == 0) == zeroed
    if not zeroed:
        assert be.delta[0] >= 2.0 ** -20 - 1e-12
