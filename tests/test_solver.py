"""Production solver: every form reaches 1e-10 on the real and generated problems, which an
independent high-precision recomputation from the *written file* confirms; presolve does not
change the answer; zero coefficients never divide; failures are diagnosed, never NaN."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import mpmath
import numpy as np
import pytest

import rfverify
from rfverify.bench import HighPrecisionChecker
from rfverify.cli import main
from rfverify.scenes.random_problems import random_local_problem, random_problem
from rfverify.solver import Status, solve

FORMS = ["jqinv", "qp2", "reduced", "reduced_factored", "noscaling"]
BUNDLED = ["chute", "chute-dat", "sphere", "cube", "sphere-from-global"]


def recheck_file(path, problem, dps=40):
    """The tests' one deliberately independent oracle: rfverify's criterion recomputed from the
    solution stored in ``path``, in ``dps``-digit mpmath with scalar loops, from the problem
    data alone — separate code from :mod:`rfverify.model.measures`, same definitions:

    dynamics ‖Mv − Hr − f‖∞/max(‖Mv‖, ‖Hr‖, ‖f‖, ‖M‖‖v‖); velocity ‖u − Hᵀv − w‖∞/U;
    cone violations of r ∈ K over R and of u ∈ K* over U; complementarity |rᵀu|/E,
    E = max(fᵀM⁻¹f, ‖w‖²/max_k Σ_j H_jk²/M_jj);
    U = max(‖u‖, ‖Hᵀv‖, ‖w‖, ‖Hᵀ‖‖v‖, ‖HᵀM⁻¹f + w‖), R = max(‖r‖, ‖f‖/max_k‖h_k‖₂).
    """
    from scipy.sparse.linalg import splu

    with h5py.File(path, "r") as fh:
        v = fh["solution/v"][()]
        u = fh["solution/u"][()]
        r = fh["solution/r"][()]
    M = problem.M_sym.tocoo()
    H = problem.H.tocoo()
    v_free = splu(problem.M_sym.tocsc()).solve(problem.f)  # data scales: float64 is enough
    u0 = float(np.max(np.abs(problem.H.T @ v_free + problem.w)))
    col = np.sqrt(np.asarray(problem.H.power(2).sum(axis=0)).ravel())
    r0 = float(np.max(np.abs(problem.f))) / float(col.max())
    nM = float(abs(problem.M_sym).sum(axis=1).max())
    nHT = float(abs(problem.H).sum(axis=0).max())
    with mpmath.workdps(dps):
        mpf = mpmath.mpf
        V = [mpf(float(x)) for x in v]
        U = [mpf(float(x)) for x in u]
        R = [mpf(float(x)) for x in r]
        Mv = [mpf(0)] * problem.n_dofs
        for i, j, x in zip(M.row, M.col, M.data):
            Mv[i] += mpf(float(x)) * V[j]
        Hr = [mpf(0)] * problem.n_dofs
        HTv = [mpf(0)] * (5 * problem.n_contacts)
        for i, j, x in zip(H.row, H.col, H.data):
            Hr[i] += mpf(float(x)) * R[j]
            HTv[j] += mpf(float(x)) * V[i]
        f = [mpf(float(x)) for x in problem.f]
        w = [mpf(float(x)) for x in problem.w]

        def amax(a):
            return max(abs(x) for x in a)

        dyn = amax([a - b - c for a, b, c in zip(Mv, Hr, f)]) / max(amax(Mv), amax(Hr), amax(f), nM * amax(V))
        u_scale = max(amax(U), amax(HTv), amax(w), nHT * amax(V), mpf(u0))
        r_scale = max(amax(R), mpf(r0))
        vel = amax([a - b - c for a, b, c in zip(U, HTv, w)]) / u_scale
        d = problem.M_sym.diagonal()
        W_diag = np.asarray(problem.H.power(2).multiply(1.0 / d[:, None]).sum(axis=0)).ravel()
        energy = max(abs(float(problem.f @ v_free)), float(np.max(np.abs(problem.w))) ** 2 / float(W_diag.max()))
        comp = abs(mpmath.fsum(a * b for a, b in zip(U, R))) / energy
        primal, dual = mpf(0), mpf(0)
        for i in range(problem.n_contacts):
            m_, mr = mpf(float(problem.mu[i])), mpf(float(problem.mu_r[i]))
            rN, rT, rR = R[5 * i], mpmath.hypot(R[5 * i + 1], R[5 * i + 2]), mpmath.hypot(R[5 * i + 3], R[5 * i + 4])
            uN, uT, uR = U[5 * i], mpmath.hypot(U[5 * i + 1], U[5 * i + 2]), mpmath.hypot(U[5 * i + 3], U[5 * i + 4])
            primal = max(primal, rT - m_ * rN, rR - mr * rN, -rN)
            dual = max(dual, m_ * uT + mr * uR - uN, -uN)
        return {"dynamics": float(dyn), "velocity": float(vel), "complementarity": float(comp),
                "primal_cone": float(primal / r_scale), "dual_cone": float(dual / u_scale)}


def _solve_and_recheck(problem, method, tmp_path, tol=1e-10, **options):
    res = solve(problem, method=method, tol=tol, **options)
    path = tmp_path / f"sol-{method}.h5"
    rfverify.save(problem.with_solution(rfverify.StoredSolution(res.v, res.u, res.r)), path)
    return res, recheck_file(path, problem)


@pytest.mark.parametrize("method", FORMS)
@pytest.mark.parametrize("name", BUNDLED)
def test_bundled_problems_reach_1e_10_verified(name, method, tmp_path):
    problem = rfverify.load(f"bundled:{name}")
    res, chk = _solve_and_recheck(problem, method, tmp_path)
    if name == "sphere-from-global":
        # its printed W is indefinite (eigenvalue −2.1e-9): the lifting is solved, the file's
        # own problem u = W r + q is not, and the status says so (issue 26)
        assert res.status is not Status.SOLVED and "solved on the lifting" in res.message
        return
    assert res.status is Status.SOLVED, res.message
    assert res.criterion <= 1e-10
    assert chk["dynamics"] <= 1e-10 and chk["velocity"] <= 1e-12
    assert chk["complementarity"] <= 1e-10
    assert chk["dual_cone"] <= 1e-10 and chk["primal_cone"] <= 1e-12


@pytest.mark.parametrize("seed", [0, 1])
def test_generated_problem_jqinv_verified(seed, tmp_path):
    problem = random_problem(60, 90, seed=seed, mu_zero_fraction=0.1, mu_r_zero_fraction=0.2,
                             free_bodies=4)
    res, chk = _solve_and_recheck(problem, "jqinv", tmp_path)
    assert res.status is Status.SOLVED, res.message
    assert chk["dynamics"] <= 1e-10 and chk["complementarity"] <= 1e-10 and chk["velocity"] <= 1e-12
    assert chk["dual_cone"] <= 1e-10 and chk["primal_cone"] <= 1e-12


def test_clarabel_peer_agrees_in_v():
    problem = random_problem(20, 30, seed=3)
    ours = solve(problem, method="jqinv", tol=1e-10)
    peer = solve(problem, method="clarabel", tol=1e-10)
    assert ours.success
    assert peer.status in (Status.SOLVED, Status.ALMOST_SOLVED), peer.message
    assert np.max(np.abs(ours.v - peer.v)) <= 1e-5 * np.max(np.abs(ours.v))


def test_clarabel_solved_is_not_taken_on_its_word():
    # On this small PrimitiveSoup scene Clarabel reports Solved at tol 1e-10; by rfverify's
    # criterion its answer has complementarity 6.7e-9 (measured), and the recheck agrees.
    problem = rfverify.load(SCENES_DIR / "PrimitiveSoup-ndof-36-nc-13-0.hdf5")
    res = solve(problem, method="clarabel", tol=1e-10)
    assert res.extras["clarabel_status"] == "Solved"
    assert res.criterion > 1e-10 and res.status is not Status.SOLVED
    assert HighPrecisionChecker(problem, 40).criterion(res.v, res.u, res.r)["max"] > 1e-10


@pytest.mark.parametrize("method", FORMS)
def test_zero_coefficients_never_divide(method):
    problem = random_problem(15, 24, seed=7, mu_zero_fraction=0.3, mu_r_zero_fraction=0.4)
    assert np.any(problem.mu == 0) and np.any(problem.mu_r == 0)
    assert np.any((problem.mu == 0) & (problem.mu_r == 0))
    with np.errstate(divide="raise", invalid="raise"):
        res = solve(problem, method=method, tol=1e-10)
    assert res.status is Status.SOLVED, res.message
    kinds = res.presolve["cone_kinds"]
    assert kinds["coulomb"] and kinds["rolling"] and kinds["normal"]
    # Components that a zero coefficient forces to zero are exactly zero.
    rc = res.r.reshape(-1, 5)
    assert np.all(rc[problem.mu == 0, 1:3] == 0)
    assert np.all(rc[problem.mu_r == 0, 3:5] == 0)


@pytest.mark.parametrize("method", FORMS)
def test_presolve_does_not_change_the_answer(method):
    # With the paper's σ rule the path depends on μ, μ_a and α_a only, which presolve leaves
    # alone, so any difference is presolve's.  (The default hybrid rule switches phase on
    # the criterion, which is evaluated per component: split and unsplit runs then take
    # different paths to different points of this ill-conditioned problem — v 7e-8 and 3e-7
    # from its 12-digit solution at criteria 4e-13 and 9e-12, measured.)
    problem = random_problem(12, 16, seed=11, free_bodies=5)  # all μ, μr > 0
    on = solve(problem, method=method, tol=1e-11, sigma_rule="paper")
    off = solve(problem, method=method, tol=1e-11, sigma_rule="paper", reduce_cones=False, drop_free_bodies=False,
                split_components=False)
    assert on.success and off.success, (on.message, off.message)
    assert on.presolve["free_dofs"] >= 30  # the 5 free bodies, plus any body no contact drew
    scale = np.max(np.abs(on.v))
    assert np.max(np.abs(on.v - off.v)) <= 1e-8 * scale
    assert np.max(np.abs(on.r - off.r)) <= 1e-7 * np.max(np.abs(on.r))


def test_free_bodies_get_v_equals_Minv_f():
    problem = random_problem(4, 5, seed=2, free_bodies=3)
    res = solve(problem)
    free = problem.contact_free_dofs
    assert free.size == 18
    np.testing.assert_allclose(problem.M_sym[free][:, free] @ res.v[free], problem.f[free], rtol=1e-13,
                               atol=1e-13 * np.abs(problem.f[free]).max())


def test_unreduced_lifting_refuses_zero_coefficients():
    problem = random_problem(5, 6, seed=1, mu_zero_fraction=0.5)
    with pytest.raises(ValueError, match="mu = 0"):
        solve(problem, reduce_cones=False)


def test_forced_numerical_failure_is_diagnosed():
    problem = rfverify.load("bundled:chute")
    res = solve(problem, method="jqinv", tol=1e-25, max_iter=60)
    assert res.status in (Status.NUMERICAL_ERROR, Status.INSUFFICIENT_PROGRESS, Status.MAX_ITERATIONS)
    assert "iteration" in res.message
    assert np.all(np.isfinite(res.v)) and np.all(np.isfinite(res.r))
    # The best iterate is returned: it is as good as the 1e-10 solve.
    assert res.criterion <= 1e-10


def test_trace_columns():
    res = solve(rfverify.load("bundled:cube"))
    lengths = {k: len(v) for k, v in res.trace.items()}
    assert len(set(lengths.values())) == 1 and lengths["iter"] == res.nit + 1
    assert np.all(np.diff(res.trace["time"]) >= 0)
    # Default refinement may end a solve at the inexact-Newton test (residuals ≤ 1e-4 of the
    # right-hand side, so a backward error below that); refined to 4·eps it is far smaller.
    assert np.nanmax(res.trace["solve_residual"]) < 1e-4
    exact = solve(rfverify.load("bundled:cube"), refine_tol=None)
    assert np.nanmax(exact.trace["solve_residual"]) < 1e-12
    assert np.all(res.trace["min_lam2_z"] > 0)


@pytest.mark.parametrize("method", ["jqinv", "noscaling"])
@pytest.mark.parametrize("name", ["chute", "chute-dat"])
def test_least_squares_start_and_siconos_sigma_reach_1e_10_verified(name, method, tmp_path):
    """The alternative start (Newton step from the origin at identity scaling, shifted into the
    cones) and σ rule are a different run, judged by the same independent oracle."""
    problem = rfverify.load(f"bundled:{name}")
    paper = solve(problem, method=method, tol=1e-10)
    res, chk = _solve_and_recheck(problem, method, tmp_path, start="least_squares", sigma_rule="siconos")
    assert res.trace["mu"][0] != paper.trace["mu"][0]  # the start was taken
    assert res.status is Status.SOLVED, res.message
    assert chk["dynamics"] <= 1e-10 and chk["complementarity"] <= 1e-10 and chk["velocity"] <= 1e-12
    assert chk["dual_cone"] <= 1e-10 and chk["primal_cone"] <= 1e-12


def test_bad_arguments():
    problem = rfverify.load("bundled:sphere")
    with pytest.raises(ValueError, match="method"):
        solve(problem, method="magic")
    with pytest.raises(TypeError, match="unknown solver option"):
        solve(problem, refine=3)
    with pytest.raises(ValueError, match="tol"):
        solve(problem, tol=-1)
    with pytest.raises(ValueError, match="start"):
        solve(problem, start="origin")
    for bad in ("exact", 0.0, 2.0, True):
        with pytest.raises(ValueError, match="refine_tol"):
            solve(problem, refine_tol=bad)
    assert solve(problem, refine_tol=1e-14).success and solve(problem, refine_tol=None).success


def test_cli_solve_json_and_out(capsys, tmp_path):
    out = tmp_path / "s.h5"
    code = main(["solve", "bundled:chute", "--json", "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    s = json.loads(captured.out)
    assert s["status"] == "Solved" and s["iterations"] > 0
    assert s["criterion"] <= 1e-10 and s["measures"]["max"] == s["criterion"]
    back = rfverify.load(out)
    assert back.solution is not None and back.solution.v.shape == (768,)
    chk = recheck_file(out, back)
    assert chk["dynamics"] <= 1e-10 and chk["complementarity"] <= 1e-10


def test_cli_solve_exit_code_when_tolerance_missed(capsys):
    code = main(["solve", "bundled:chute", "--tol", "1e-25", "--max-iter", "30"])
    out = capsys.readouterr().out
    assert code == 1
    assert "status" in out


def test_cli_solve_verbose_table(capsys):
    code = main(["solve", "bundled:sphere", "--verbose"])
    out = capsys.readouterr().out
    assert code == 0
    assert "settings:" in out and "pinfeas" in out and "presolve:" in out


def test_components_are_solved_separately_with_the_same_answer():
    # Mostly ground contacts on many bodies: the body–contact graph falls apart.
    problem = random_problem(40, 25, seed=0, ground_fraction=0.8, free_bodies=3)
    split = solve(problem, tol=1e-13, max_components=64)
    whole = solve(problem, tol=1e-13, split_components=False)
    assert split.success and whole.success, (split.message, whole.message)
    assert split.presolve["components"] > 5
    assert "components" not in whole.presolve
    assert len(split.extras["component_runs"]) == split.presolve["components"]
    # The stopping criterion at 1e-13 pins v down to ~7 digits only (measured: 2.5e-7 against
    # a 1e-15 solve; that gap is what the certification issue is about), so the two runs,
    # whose iterates differ, are compared at that level.
    assert np.max(np.abs(split.v - whole.v)) <= 1e-6 * np.max(np.abs(whole.v))
    assert np.max(np.abs(split.r - whole.r)) <= 1e-6 * np.max(np.abs(whole.r))
    # The combined measures are recomputed over the whole problem, not taken from one part.
    assert max(split.pinfeas, split.dinfeas, split.mu) <= 1e-13


def test_too_many_components_are_solved_together():
    problem = random_problem(40, 25, seed=0, ground_fraction=0.8)
    res = solve(problem, max_components=2)
    assert res.success
    assert "solved together" in str(res.presolve["components"])


SCENES_DIR = Path(__file__).parent / "data" / "scenes"
HARD_DIR = Path(__file__).parent / "data" / "hard"
HARD = ["Lattice-ndof-24-nc-16-0", "Millimetre-ndof-72-nc-21-1"]


@pytest.mark.parametrize("method", FORMS)
@pytest.mark.parametrize("name", HARD)
def test_hard_scene_instances_verified(name, method, tmp_path):
    # jqinv (the form the project relies on) and noscaling must solve both; any form that
    # claims Solved must be confirmed by the independent recheck.  Measured: reduced ends
    # AlmostSolved on Millimetre (|uᵀr|/n stays ~2e-8 g·mm²/s² once λ2 underflows) and qp2
    # stalls on Lattice — honest statuses, not false claims.
    problem = rfverify.load(HARD_DIR / f"{name}.hdf5")
    res, chk = _solve_and_recheck(problem, method, tmp_path)
    if method in ("jqinv", "noscaling"):
        assert res.status is Status.SOLVED, res.message
    if res.success:
        assert chk["dynamics"] <= 1e-10 and chk["complementarity"] <= 1e-10 and chk["velocity"] <= 1e-12
        assert chk["dual_cone"] <= 1e-10 and chk["primal_cone"] <= 1e-12
    else:
        assert res.status is not Status.SOLVED and np.all(np.isfinite(res.v))


RESCALED_HARD = ["MassRatio-1e9-ndof-24-nc-4-0", "MassRatio-1e9-ndof-24-nc-6-0"]


@pytest.mark.parametrize("name", RESCALED_HARD)
def test_a_step_to_another_scale_restarts_the_stall_count(name, tmp_path):
    # Mass ratio 1e9 (data/hard/README.md): one step takes a light sphere's reaction 1e5 times
    # its start and μ up 1e3–1e7-fold; the measures then fall five-fold a step, but stayed above
    # their bests from before the move for the 8-iteration stall window, and every form ended
    # InsufficientProgress (18 of 24 generated MassRatio problems at 1e9).
    from rfverify.solver.termination import RESCALED

    problem = rfverify.load(HARD_DIR / f"{name}.hdf5")
    res, chk = _solve_and_recheck(problem, "auto", tmp_path)
    assert res.status is Status.SOLVED, res.message
    assert chk["dynamics"] <= 1e-10 and chk["complementarity"] <= 1e-10 and chk["velocity"] <= 1e-12
    assert chk["dual_cone"] <= 1e-10 and chk["primal_cone"] <= 1e-12
    runs = [c["trace"] for c in res.extras.get("component_runs", [])] or [res.trace]
    jumps = [np.asarray(t["mu"]) for t in runs]
    assert any(np.any(mu[1:] > RESCALED * mu[:-1]) for mu in jumps)  # the case the rule is for


class _Measures:
    def __init__(self, value):
        self.velocity = self.dual_cone = self.dynamics = self.primal_cone = 0.0
        self.complementarity = self.max = value


@pytest.mark.parametrize("after_the_jump", ["falls", "stays"])
def test_stall_count_after_mu_jumps(after_the_jump):
    # A run whose μ jumps 1e7-fold and then falls five-fold a step is not stalled (it would have
    # been at its 8th step: its best is from before the jump); one that stays at the new scale is.
    from rfverify.solver.result import Settings
    from rfverify.solver.termination import Termination

    term = Termination(Settings(tol=1e-10))
    values = [1.0, 0.1, 1e-2, 1e-3] + [1e4 * (0.2 if after_the_jump == "falls" else 0.99) ** k for k in range(12)]
    verdicts = []
    for k, value in enumerate(values):
        verdicts.append(term.observe(k, _Measures(value), (0.0, 0.0, value), None))
        term.after_step(1.0)
    stalled = [v for v in verdicts if v is not None]
    if after_the_jump == "falls":
        assert not stalled
    else:
        assert stalled and stalled[0].status is Status.INSUFFICIENT_PROGRESS
        assert verdicts.index(stalled[0]) == 4 + 8  # the count restarted at the jump


def test_refinement_resolves_the_primal_block(tmp_path):
    # Refinement that stops at a 0.5 contraction rate (LAPACK's) ended this lattice at
    # pinfeas 1.5e-9 (AlmostSolved); the 0.8 rate solves it.  Measured, see data/hard/README.md.
    # It also needs the float64 phase to end at the first float64 solve that falls short
    # (Settings.longdouble_below): switching on the criterion alone ended it InsufficientProgress.
    problem = rfverify.load(HARD_DIR / "Lattice-ndof-360-nc-274-1.hdf5")
    res, chk = _solve_and_recheck(problem, "jqinv", tmp_path)
    assert res.status is Status.SOLVED, res.message
    assert res.criterion <= 1e-10
    assert chk["dynamics"] <= 1e-10 and chk["complementarity"] <= 1e-10 and chk["velocity"] <= 1e-12


def test_redundant_contacts_keep_the_unregularised_factorisation():
    # Once an iteration needed the factorisation without δ, the next one tries it first, so
    # such iterations cost one factorisation, not two (see KKTSystem.prefer_unregularised).
    problem = rfverify.load(HARD_DIR / "Lattice-ndof-24-nc-16-0.hdf5")
    res = solve(problem, method="jqinv", split_components=False, tol=1e-12)
    n_unreg = res.extras["unregularised_factorisations"]
    assert res.success and n_unreg >= 3
    assert res.extras["factorisations"] < res.nit + n_unreg


@pytest.mark.parametrize("method", FORMS)
def test_unrefined_solves_take_the_regularisation_fallback_only_where_it_exists(method):
    # Without refinement every predictor solve ends far above the fallback threshold, so the
    # δ fallback runs at each iteration; forms (16) and (6) have no δ to drop and must not
    # enter it (a crash on reduced_factored before the regularisable flag).
    problem = rfverify.load("bundled:chute")
    res = solve(problem, method=method, refine_max=0)
    assert res.status in (Status.SOLVED, Status.ALMOST_SOLVED), res.message
    n_unreg = res.extras["unregularised_factorisations"]
    assert (n_unreg > 0) if method in ("jqinv", "qp2", "reduced") else (n_unreg == 0)


def test_always_regularising_stalls_on_redundant_contacts():
    # The mechanism behind adaptive_reg: with −δI on the dr̃ block at every iteration the
    # lifted primal residual of the lattice cannot fall (pinfeas stuck near 0.3), the split of
    # u0 between the lifted cones drifts, and the gap of the returned answer stalls above tol
    # (measured: criterion 2.8e-8).  If this starts passing, adaptive_reg may no longer be
    # needed: re-measure before removing it.
    problem = rfverify.load(HARD_DIR / "Lattice-ndof-24-nc-16-0.hdf5")
    fixed = solve(problem, method="jqinv", adaptive_reg=False)
    adaptive = solve(problem, method="jqinv")
    assert fixed.status is Status.INSUFFICIENT_PROGRESS and fixed.pinfeas > 1e-3 and fixed.criterion > 1e-9
    assert adaptive.success and adaptive.extras["unregularised_factorisations"] > 0

class _ProtocolOnly:
    """A form seen through the KKTSolver protocol only: any other attribute access fails."""

    ALLOWED = {"name", "symmetric", "update", "solve", "set_refinement_dtype", "factor_count", "unregularised_count",
               "failure"}

    def __init__(self, inner):
        object.__setattr__(self, "_inner", inner)

    def __getattr__(self, name):
        if name not in self.ALLOWED:
            raise AssertionError(f"the driver used {name!r}, which is not part of the KKTSolver protocol")
        return getattr(self._inner, name)


@pytest.mark.parametrize("method", FORMS)
def test_driver_uses_the_kkt_back_end_only_through_its_protocol(method, monkeypatch):
    from rfverify.solver import forms, ipm

    wrapped = {name: (lambda cls: (lambda *a, **k: _ProtocolOnly(cls(*a, **k))))(cls) for name, cls in forms.FORMS.items()}
    monkeypatch.setattr(ipm, "FORMS", wrapped)
    res = solve(rfverify.load("bundled:chute"), method=method)
    assert res.success, res.message


def _system_at_an_iterate(method, tol=1e-6, **kw):
    """A KKT form at the final iterate of a solve of the bundled cube to ``tol``, and its
    unreduced operator A = [[M, −H̃ᵀ, 0], [−H̃, 0, J], [0, Q_{p⁻¹}Jᵀ, Q_p]] (noscaling:
    [0, Arw(z)Jᵀ, Arw(s)]) formed densely, independently of the form's own operators."""
    from scipy.linalg import block_diag

    from rfverify import jordan
    from rfverify.model.lifting import lift
    from rfverify.solver.cones import ProductCone
    from rfverify.solver.forms import FORMS as KFORMS
    from rfverify.solver.kkt import ScalingPoint

    problem = rfverify.load("bundled:cube")
    res = solve(problem, tol=tol)
    lp = lift(problem)
    cones = ProductCone(lp.n3, lp.n1)
    z = np.asarray(res.extras["z"], dtype=np.float64)
    s = lp.J.T @ np.asarray(res.extras["r_t"], dtype=np.float64)
    system = KFORMS[method](problem.M_sym, lp.H_t, lp.J, cones, **kw)
    if method == "noscaling":
        point = ScalingPoint(z=z, s=s)
        blk = lambda x: [jordan.arrow(x[3 * c:3 * c + 3]) for c in range(lp.n3)]  # noqa: E731
        Q1, Q2 = blk(z), blk(s)  # third row: [0, Arw(z) Jᵀ, Arw(s)]
    else:
        p, p_inv, _, _ = cones.nt_scaling(z, s)
        point = ScalingPoint(p=p, p_inv=p_inv)
        Q1 = [jordan.quad_matrix(p_inv[3 * c:3 * c + 3]) for c in range(lp.n3)]
        Q2 = [jordan.quad_matrix(p[3 * c:3 * c + 3]) for c in range(lp.n3)]
    assert lp.n1 == 0 and system.update(point)
    m, nk, nz = problem.n_dofs, lp.nk, lp.nz
    A = np.zeros((m + nk + nz, m + nk + nz))
    A[:m, :m] = problem.M_sym.toarray()
    A[:m, m:m + nk] = -lp.H_t.T.toarray()
    A[m:m + nk, :m] = -lp.H_t.toarray()
    A[m:m + nk, m + nk:] = lp.J.toarray()
    A[m + nk:, m:m + nk] = block_diag(*Q1) @ lp.J.T.toarray()
    A[m + nk:, m + nk:] = block_diag(*Q2)
    return system, A, (m, m + nk)


@pytest.mark.parametrize("method", ["jqinv", "qp2", "noscaling"])
def test_backward_error_basis_is_the_unreduced_operator(method):
    """Every form reports its refinement backward error against the block-row norms of the
    same unreduced operator, formed densely here and its norms computed directly."""
    system, A, (m, mk) = _system_at_an_iterate(method)
    rows = np.abs(A).sum(axis=1)
    direct = [rows[:m].max(), rows[m:mk].max(), rows[mk:].max()]
    assert np.allclose(system.block_norms, direct, rtol=1e-12), (system.block_norms, direct)


@pytest.mark.parametrize("method", ["jqinv", "qp2"])
def test_inexact_newton_refinement_claims_only_what_holds(method):
    """A solve ended by the inexact-Newton test (refine_tol="adaptive") has every block
    residual, recomputed with the dense operator, at most the forcing term times that block's
    right-hand side; it takes fewer steps than refining to 4·eps; without forcing no solve
    says it was forced.  Right-hand sides as late in a run: an iterate at 1e-9, residuals
    far below ‖A‖‖x‖."""
    forcing = 1e-4
    rng = np.random.default_rng(11)
    system, A, (m, mk) = _system_at_an_iterate(method, tol=1e-9, forcing=forcing)
    exact, _, _ = _system_at_an_iterate(method, tol=1e-9)
    n = A.shape[0]
    forced_seen = 0
    for trial in range(6):
        rhs = rng.standard_normal(n) * np.concatenate([np.full(m, 1e-9), np.full(mk - m, 1e-10),
                                                       np.full(n - mk, 1e-8)])
        a, b, c = rhs[:m], rhs[m:mk], rhs[mk:]
        info = system.refined(a, b, c)
        x = np.concatenate([info.dv, info.dr, info.dz]).astype(np.float64)
        res = rhs - A @ x
        if info.forced:
            forced_seen += 1
            for lo, hi in ((0, m), (m, mk), (mk, n)):
                assert np.abs(res[lo:hi]).max() <= 1.01 * forcing * np.abs(rhs[lo:hi]).max()
            assert info.steps <= exact.refined(a, b, c).steps
        assert not exact.refined(a, b, c).forced
    if method == "jqinv":  # the default form: these solves do end early
        assert forced_seen > 0


def test_auto_goes_on_to_the_next_form_where_jqinv_stalls(tmp_path):
    """On a lifted local problem with a singular W, jqinv stalls (measured: complementarity
    2.4e-7 after 26 iterations) and the reduced form solves it; auto returns the reduced run,
    rechecked independently from the written file, and says what it tried."""
    problem = random_local_problem(60, seed=0)
    alone = solve(problem, method="jqinv")
    assert not alone.success
    res, chk = _solve_and_recheck(problem, "auto", tmp_path)
    assert res.success and res.method == "reduced", res.message
    assert [a["method"] for a in res.extras["attempts"]] == ["jqinv", "reduced"]
    assert res.extras["attempts"][0]["status"] == str(alone.status)
    assert "jqinv" in res.message and "reduced" in res.message
    assert max(chk["dynamics"], chk["complementarity"]) <= 1e-10 and chk["velocity"] <= 1e-12


def test_cli_json_names_the_form_auto_returned(tmp_path, capsys):
    path = tmp_path / "local.h5"
    rfverify.save(random_local_problem(60, seed=0), path)
    assert main(["solve", str(path), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["requested_method"] == "auto" and out["method"] == "reduced"
    assert [a["method"] for a in out["attempts"]] == ["jqinv", "reduced"] and out["success"]


def test_auto_is_jqinv_where_jqinv_solves_and_stops_on_the_users_word():
    problem = rfverify.load("bundled:chute")
    res = solve(problem)  # auto is the default
    assert res.success and res.method == "jqinv" and len(res.extras["attempts"]) == 1
    assert np.array_equal(res.v, solve(problem, method="jqinv").v)
    # A callback that stops the run stops the sequence: no other form is tried.
    stopped = solve(random_local_problem(60, seed=0), callback=lambda info: info.iteration >= 2)
    assert stopped.status is Status.STOPPED and len(stopped.extras["attempts"]) == 1
    # The time limit holds for the whole sequence.
    limited = solve(random_local_problem(60, seed=0), time_limit=1e-3)
    assert limited.status is Status.MAX_TIME and len(limited.extras["attempts"]) == 1


@pytest.mark.parametrize("seed", [3, 4])
def test_float64_start_then_extended_arithmetic(seed):
    """The default run starts in float64 and switches to longdouble for good at the iteration
    it reports, never later than the first iterate whose criterion is ≤ longdouble_below, and
    its answer is verified; longdouble_below=None is longdouble throughout."""
    problem = random_problem(30, 60, seed=seed)
    # longdouble_below = 1e-6, well above tol, so that the switch happens before the end.
    res = solve(problem, method="jqinv", keep_iterates=True, split_components=False, longdouble_below=1e-6)
    assert res.success and res.criterion <= 1e-10
    (k,) = res.extras["longdouble_from"]
    assert 0 < k < len(res.extras["iterates"])
    dtypes = [v.dtype for v, r_t, z in res.extras["iterates"]]
    # Iterate k is the float64 one the switch converts; the steps from it on are longdouble.
    assert set(dtypes[:k + 1]) == {np.dtype(np.float64)} and set(dtypes[k + 1:]) == {np.dtype(np.longdouble)}
    crit = res.trace["criterion"]
    assert np.all(crit[:k] > res.settings.longdouble_below)
    full = solve(problem, method="jqinv", keep_iterates=True, split_components=False, longdouble_below=None)
    assert full.extras["longdouble_from"] == [0] and full.success
    assert {v.dtype for v, r_t, z in full.extras["iterates"]} == {np.dtype(np.longdouble)}
    # Both are answers to the same problem: they agree far beyond the tolerance's scale.
    assert np.max(np.abs(res.v - full.v)) <= 1e-6 * max(np.max(np.abs(full.v)), 1.0)


def test_data_beyond_float64_comfort_start_extended():
    p = random_problem(4, 6, seed=2)
    # beyond 2^128 (the float64 phase's comfort) but inside 2^±200, which is solved unscaled
    s = 2.0 ** 150
    big = rfverify.Problem.from_arrays(p.M * s, p.H * s, p.f * s, p.w, p.mu, p.mu_r)
    res = solve(big, method="jqinv", split_components=False)
    assert res.extras["longdouble_from"] == [0]


@pytest.mark.parametrize("bad", [0.0, -1e-6, float("nan"), True, "1e-6"])
def test_extended_below_is_checked(bad):
    with pytest.raises(ValueError, match="longdouble_below"):
        solve(rfverify.load("bundled:cube"), longdouble_below=bad)


def test_hybrid_sigma_is_mehrotras_far_and_the_papers_near(monkeypatch):
    """The default σ rule uses Mehrotra's cube, floored at 0.2, while the iterate's criterion is
    above 1e-4 and the paper's rule from there on — decided per iteration from the criterion
    the trace shows — and each phase's σ is that rule's value."""
    from rfverify.algorithm import rules as ipm

    calls = []
    real = ipm.centring

    def recording(rule, mu_aff, mu, alpha_aff):
        calls.append((rule, mu_aff, mu, alpha_aff))
        return real(rule, mu_aff, mu, alpha_aff)

    monkeypatch.setattr(ipm, "centring", recording)
    res = solve(rfverify.load(HARD_DIR / "Millimetre-ndof-72-nc-21-1.hdf5"), method="jqinv", split_components=False)
    assert res.success and res.settings.sigma_rule == "hybrid"
    crit, sigma = res.trace["criterion"][:-1], res.trace["sigma"][:-1]
    assert [c[0] for c in calls] == ["mehrotra" if c > ipm.HYBRID_SWITCH else "paper" for c in crit]
    assert {c[0] for c in calls} == {"mehrotra", "paper"}
    for (rule, mu_aff, mu, alpha_aff), s in zip(calls, sigma):
        ratio = max(mu_aff, 0.0) / mu
        if rule == "mehrotra":
            expected = max(ipm.HYBRID_SIGMA_FLOOR, min(1.0, ratio ** 3))
        else:
            expected = min(1.0, ratio ** (max(1.0, 3 * alpha_aff) if mu < 1e-5 else 1.0))
        assert s == pytest.approx(expected, rel=1e-12)
    # The floor is reached on this problem (it is what keeps the path centred).
    assert any(c[0] == "mehrotra" and (max(c[1], 0) / c[2]) ** 3 < ipm.HYBRID_SIGMA_FLOOR for c in calls)


def test_default_start_and_sigma_rule_take_fewer_iterations_and_stay_verified(tmp_path):
    """What the defaults are for (docs/DECISIONS.md, "σ rule and start"): on committed scenes
    whose start is far from their scale (a Millimetre, a Chute, a soup, a pile) the hybrid σ
    rule and the velocity-scaled start take fewer iterations than the paper's rules (68
    against 77, measured), and every answer still passes the independent recheck at 1e-10.
    (On small easy problems the floor costs a few iterations: +2% over the whole sweep.)"""
    names = ["hard/Millimetre-ndof-72-nc-21-1.hdf5", "scenes/PrimitiveSoup-ndof-36-nc-13-0.hdf5",
             "scenes/SpheresPile-ndof-36-nc-6-1.hdf5", "hard/Chute-ndof-24-nc-4-0.hdf5"]
    new = old = 0
    for name in names:
        problem = rfverify.load(HARD_DIR.parent / name)
        res, chk = _solve_and_recheck(problem, "jqinv", tmp_path)
        assert res.success, (name, res.message)
        assert chk["dynamics"] <= 1e-10 and chk["complementarity"] <= 1e-10 and chk["velocity"] <= 1e-12
        paper = solve(problem, method="jqinv", sigma_rule="paper", start="paper")
        assert paper.success
        new, old = new + res.nit, old + paper.nit
    assert new < old, (new, old)


def test_velocity_scaled_start_is_z_on_the_scale_of_w():
    """start="velocity_scaled": z = θ·e with θ = max(1, rms(w̃)), r̃ as the paper's start, so
    μ at iteration 0 is θ·(number of cones)/n; θ = 1 (the paper's start) when rms(w̃) ≤ 1."""
    from rfverify.model.lifting import lift
    from rfverify.solver.ipm import velocity_scale

    p = random_problem(6, 10, seed=5)
    for factor in (1.0, 1e3):
        q = rfverify.Problem.from_arrays(p.M, p.H, p.f, p.w * factor, p.mu, p.mu_r)
        lp = lift(q)
        theta = velocity_scale(lp.w_t)
        assert (theta == 1.0) if factor == 1.0 else theta == pytest.approx(np.sqrt(np.mean(lp.w_t ** 2)))
        n_cones = lp.n3 + lp.n1
        res = solve(q, method="jqinv", max_iter=1, split_components=False)
        paper = solve(q, method="jqinv", max_iter=1, split_components=False, start="paper")
        assert res.trace["mu"][0] == pytest.approx(theta * n_cones / q.n_contacts, rel=1e-12)
        assert paper.trace["mu"][0] == pytest.approx(n_cones / q.n_contacts, rel=1e-12)


@pytest.mark.parametrize("name", ["elastic/ElasticBlock-ndof-252-nc-28-0.hdf5", "Lattice-ndof-54-nc-36-0.hdf5"])
def test_slow_refinement_takes_the_factorisation_without_delta(name, monkeypatch):
    """A predictor solve that needs more than SLOW_REFINEMENT_STEPS refinement steps is slowed
    by δ: the form factors without it.  Measured: on the FE block 8 refinement steps in all
    against 88 with the trigger off; on the lattice 4 against 22, and its run no longer
    needs the switch to longdouble that the stalled float64 solves caused."""
    from rfverify.solver import kkt

    problem = rfverify.load(SCENES_DIR / name)
    res = solve(problem, method="jqinv", split_components=False)
    monkeypatch.setattr(kkt, "SLOW_REFINEMENT_STEPS", 10 ** 6)
    off = solve(problem, method="jqinv", split_components=False)
    assert res.success and off.success
    assert res.extras["unregularised_factorisations"] > off.extras["unregularised_factorisations"]
    assert 2 * res.trace["refine_steps"].sum() < off.trace["refine_steps"].sum()
    if name.startswith("Lattice"):
        assert res.extras["longdouble_from"] == [None] and off.extras["longdouble_from"] != [None]


@pytest.mark.parametrize("option, bad", [("sigma_rule", "mehrotra"), ("sigma_rule", "cubic"), ("start", "origin")])
def test_sigma_rule_and_start_are_checked(option, bad):
    with pytest.raises(ValueError, match=option):
        solve(rfverify.load("bundled:cube"), **{option: bad})


def test_a_float64_solve_short_only_in_negligible_blocks_keeps_float64(monkeypatch):
    """The switch to the extended arithmetic after a float64 solve that fell short
    (ipm._adequate): near the solution the dual and primal right-hand sides are ~1e-10 of
    their terms, and a solve that resolves them to 1e-2 of tol × those terms, though not to
    1e-4 of themselves, gives the iteration what it needs.  On this 240-contact chute (a fresh
    seed, data/hard/README.md) at 1e-8 the run then stays in float64 and ends at the same
    answer; with the old rule (TOL_MARGIN = 0) it switched at iteration 14.  The lattice whose
    float64 solves leave its primal block unresolved still switches early, and is Solved."""
    from rfverify.solver import ipm

    chute = rfverify.load(HARD_DIR / "Chute-ndof-1200-nc-240-3.hdf5")
    lattice = rfverify.load(HARD_DIR / "Lattice-ndof-360-nc-274-1.hdf5")
    res = solve(chute, method="jqinv", tol=1e-8)
    lat = solve(lattice, method="jqinv", tol=1e-8)
    monkeypatch.setattr(ipm, "TOL_MARGIN", 0.0)
    old = solve(chute, method="jqinv", tol=1e-8)
    assert res.success and old.success and res.criterion <= 1e-8
    assert res.extras["longdouble_from"] == [None] and old.extras["longdouble_from"] != [None]
    assert res.nit == old.nit
    # the same answer in its unique parts: r is not unique on this chute (its two runs, both
    # Solved at 1e-8, differ by 4e-8 in r with numpy 2.4.6, by 1e-13 in v and Hr)
    assert np.max(np.abs(res.v - old.v)) <= 1e-10 * np.max(np.abs(old.v))
    Hr, Hr_old = chute.H @ res.r, chute.H @ old.r
    assert np.max(np.abs(Hr - Hr_old)) <= 1e-10 * np.max(np.abs(Hr_old))
    (k,) = lat.extras["longdouble_from"]
    assert lat.success and k is not None and lat.trace["criterion"][k] > lat.settings.longdouble_below


def test_adequate_solve_rule():
    from rfverify.solver.ipm import REFINE_FORCING, TOL_MARGIN, _adequate
    from rfverify.solver.kkt import SolveInfo

    def info(residuals, converged=False):
        return SolveInfo(np.zeros(1), np.zeros(1), np.zeros(1), 1e-12, 5, converged=converged,
                         block_residuals=residuals, rhs_norms=(1e-10, 1e-9, 1e-3))

    scales = (10.0, 30.0, 0.0)
    tol = 1e-8
    assert _adequate(info((1e-9, 1e-9, 1.0), converged=True), tol, scales)
    # Dual and primal blocks: within TOL_MARGIN·tol·scale (1e-9, 3e-9) although above 1e-4 of
    # their right-hand sides; complementarity within 1e-4 of its own.
    assert _adequate(info((0.9 * TOL_MARGIN * tol * 10, 0.9 * TOL_MARGIN * tol * 30, 0.9e-7)), tol, scales)
    assert not _adequate(info((1.1 * TOL_MARGIN * tol * 10, 1e-14, 1e-8)), tol, scales)
    assert not _adequate(info((1e-14, 1.1 * TOL_MARGIN * tol * 30, 1e-8)), tol, scales)
    # The complementarity block has no absolute floor: only its own right-hand side counts.
    assert not _adequate(info((1e-14, 1e-14, 1.1 * REFINE_FORCING * 1e-3)), tol, scales)
    assert not _adequate(info(()), tol, scales)  # no residuals recorded (a NaN solve)


def test_a_failed_factorisation_without_delta_is_not_repeated_at_the_same_matrix(monkeypatch):
    """When an iteration's factorisation without δ fails (wrong inertia or a zero pivot) and its
    predictor solve then refines badly, the δ fallback must not try the same matrix without δ
    again: it fails the same way, at the price of two factorisations.  On this 240-contact
    chute at 1e-10 that happens once (on fresh 1000/1370-contact chutes, 2–6 factorisations a
    solve); the answer is unchanged."""
    from rfverify.solver import kkt

    attempts, fallbacks = [], []
    real_try, real_update = kkt.KKTSystem._try_unregularised, kkt.KKTSystem.update
    real_refactor = kkt.KKTSystem.refactor_unregularised

    def update(self, point):
        attempts.append([])  # this matrix's attempts without δ, True where kept
        return real_update(self, point)

    def try_unregularised(self):
        ok = real_try(self)
        attempts[-1].append(ok)
        return ok

    def refactor_unregularised(self):
        fallbacks.append(self.regularised)
        return real_refactor(self)

    monkeypatch.setattr(kkt.KKTSystem, "update", update)
    monkeypatch.setattr(kkt.KKTSystem, "_try_unregularised", try_unregularised)
    monkeypatch.setattr(kkt.KKTSystem, "refactor_unregularised", refactor_unregularised)
    res = solve(rfverify.load(HARD_DIR / "Chute-ndof-1200-nc-240-3.hdf5"), method="jqinv")
    assert res.success
    assert all(False not in a[:-1] for a in attempts)  # never tried again after failing
    if not (any(fallbacks) and any(False in a for a in attempts)):
        # with numpy 2.4.6 this chute's run no longer meets a failed factorisation without δ
        pytest.skip("the δ fallback did not run on this chute with these library versions")


# ---------------------------------------------------------------- the Schur form
# (forms.SchurSystem: CHOLMOD with the optional extra "cholmod", else QDLDL; issue 27).  Its
# method name and auto's choice of it: tests/test_scale.py.

def test_schur_solves_against_the_unreduced_operator(schur_engine):
    """One unrefined solve of the Schur form solves the dense unreduced operator of the cube
    at a late iterate to a small backward error, and refinement reaches its target."""
    rng = np.random.default_rng(3)
    system, A, (m, mk) = _system_at_an_iterate("schur", tol=1e-9)
    n = A.shape[0]
    for _ in range(3):
        rhs = rng.standard_normal(n)
        x = system.solve_once(rhs)
        back = np.abs(rhs - A @ x).max() / (np.abs(A).sum(axis=1).max() * np.abs(x).max() + np.abs(rhs).max())
        assert back < 1e-10, back
        info = system.refined(rhs[:m], rhs[m:mk], rhs[mk:])
        assert info.converged and info.backward_error <= system.refine_target


@pytest.mark.parametrize("problem", ["bundled:chute", "random", "lattice"])
def test_schur_takes_the_path_of_form_16(problem, schur_engine):
    """S = M + BᵀB is form (16) with its identity block eliminated: same statuses and
    iteration counts as reduced_factored, answers agreeing far below the tolerance."""
    p = {"bundled:chute": lambda: rfverify.load("bundled:chute"),
         "random": lambda: random_problem(60, 150, seed=5),
         "lattice": lambda: rfverify.load(Path(__file__).parent / "data" / "hard" / "Lattice-ndof-360-nc-274-1.hdf5"),
         }[problem]()
    ref = solve(p, method="reduced_factored", tol=1e-10)
    res = solve(p, method="schur", tol=1e-10)
    assert res.status is Status.SOLVED and ref.status is Status.SOLVED, res.message
    assert abs(res.nit - ref.nit) <= 1
    scale = max(np.abs(ref.v).max(), 1e-300)
    assert np.abs(res.v - ref.v).max() <= 1e-6 * scale


def test_the_former_names_of_the_longdouble_settings_still_work():
    """Issue 50 renamed Settings.extended_* (longdouble, not the double-double phase) to
    longdouble_*; the former names are public API: accepted with a DeprecationWarning, readable,
    and the same run."""
    from rfverify import Settings
    from rfverify.solver.result import RENAMED_SETTINGS

    problem = rfverify.load("bundled:sphere")
    new = solve(problem, method="jqinv", longdouble_below=None)
    with pytest.warns(DeprecationWarning, match="now called 'longdouble_below'"):
        old = solve(problem, method="jqinv", extended_below=None)
    assert np.array_equal(old.v, new.v) and np.array_equal(old.r, new.r) and old.nit == new.nit
    assert old.extras["extended_from"] == old.extras["longdouble_from"] == [0]
    with pytest.warns(DeprecationWarning):
        s = Settings(extended_jordan=False, refine_extended=False)
    assert not s.longdouble_jordan and not s.extended_jordan and not s.refine_longdouble
    assert set(RENAMED_SETTINGS.values()) <= set(Settings.names())
    with pytest.raises(TypeError, match="given twice"):
        Settings(extended_below=None, longdouble_below=1e-9)


def test_auto_tries_the_papers_centring_rule_after_every_form_stalled():
    """MassRatio at 1e8 (data/hard/README.md): every form stalls under the default (hybrid) σ
    rule; auto's last resort, jqinv with the paper's rule, is Solved and returned, and the
    attempts say so.  A σ rule the caller chose is kept: then no last resort runs."""
    from rfverify.solver.result import AUTO_LAST_RESORT

    problem = rfverify.load(HARD_DIR / "MassRatio-1e8-ndof-600-nc-297-1.hdf5")
    res = rfverify.solve(problem, tol=1e-10)
    attempts = res.extras["attempts"]
    assert res.success and res.method == "jqinv" and res.settings.sigma_rule == "paper"
    assert [a["status"] for a in attempts[:-1]] == ["InsufficientProgress"] * (len(attempts) - 1)
    assert (attempts[-1]["method"], attempts[-1]["sigma_rule"]) == AUTO_LAST_RESORT
    assert "jqinv (σ rule paper): Solved" in res.message
    assert res.message.startswith("auto returned jqinv (σ rule paper) [")  # audit: it said "returned jqinv"
    chosen = rfverify.solve(problem, tol=1e-10, sigma_rule="hybrid")
    assert not chosen.success and all("sigma_rule" not in a for a in chosen.extras["attempts"])
    assert len(chosen.extras["attempts"]) == len(attempts) - 1


def test_auto_returns_a_failed_last_resort_only_in_its_list():
    """Where the last resort fails too, the answer returned is the best of auto's own forms (as
    before it existed); the last resort is listed among the attempts."""
    problem = rfverify.load("bundled:sphere-from-global")  # W as printed is not PSD: nothing is Solved
    res = rfverify.solve(problem, tol=1e-10)
    attempts = res.extras["attempts"]
    assert not res.success and attempts[-1].get("sigma_rule") == "paper"
    assert res.settings.sigma_rule == "hybrid"
    best_form = min(attempts[:-1], key=lambda a: a["criterion"])
    assert res.criterion == best_form["criterion"]


def test_auto_cut_short_by_the_time_limit_says_so(monkeypatch):
    """Audit (2026-12-08): where the time limit ran out after one form stalled and before (or
    during) the next, auto returned the stalled form's InsufficientProgress; the limit, which the
    docs say ends a run with MaxTime, was nowhere in the answer.  The limit is made to run out in
    the second form here (whatever the machine's speed): the status is MaxTime and says where."""
    import rfverify.solver as solver_module

    real = solver_module._solve

    def second_form_out_of_time(problem, form, tol, max_iter, keep_iterates, callback, **opts):
        if form not in ("auto", "jqinv"):
            opts["time_limit"] = 1e-9
        return real(problem, form, tol, max_iter, keep_iterates, callback, **opts)

    monkeypatch.setattr(solver_module, "_solve", second_form_out_of_time)
    problem = rfverify.load(str(Path(__file__).parent / "data" / "hard" / "MassRatio-1e8-ndof-600-nc-297-1.hdf5"))
    res = solve(problem, time_limit=3600)
    assert [a["status"] for a in res.extras["attempts"]] == ["InsufficientProgress", "MaxTime"]
    assert res.status is Status.MAX_TIME and not res.success
    assert "time limit of 3600 s (all forms together) ran out during reduced" in res.message
