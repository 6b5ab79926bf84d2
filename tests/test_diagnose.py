"""The diagnosis (issue 46): lockstep against exact steps in double-double, the cause decided by
the same algorithm continued in exact arithmetic, a remedy the diagnosis ran, the figure.

The inputs: the MassRatio and Lattice files of tests/data/hard (qp2 stalls there in double
while the exact algorithm meets 1e-10), bundled problems for healthy runs and runs cut short
by --max-iter, and an infeasible two-contact problem for a cause in the data."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import rfverify
from rfverify.cli import main
from rfverify.verify.diagnosis import diagnose

HARD = Path(__file__).parent / "data" / "hard"
MASSRATIO = HARD / "MassRatio-ndof-24-nc-5-0.hdf5"  # issue 46's first case
LATTICE = HARD / "Lattice-ndof-24-nc-16-0.hdf5"


def _infeasible():
    """One dof, two normal-only contacts asking v ≥ 1 and v ≤ 0.9: no solution exists."""
    H = sp.csc_matrix(np.array([[1.0, 0, 0, 0, 0, -1.0, 0, 0, 0, 0]]))
    w = np.zeros(10)
    w[0], w[5] = -1.0, 0.9
    return rfverify.Problem.from_arrays(sp.identity(1, format="csc"), H, np.zeros(1), w, np.zeros(2), np.zeros(2))


@pytest.fixture(scope="module")
def massratio():
    return diagnose(rfverify.load(MASSRATIO), method="qp2", tol=1e-10, witness_time=30)


# ---------------------------------------------------------------------- lockstep
def test_lockstep_agreement_on_a_healthy_run():
    d = diagnose(rfverify.load("bundled:cube"), tol=1e-10)
    assert d.status == "Solved" and d.success and d.failure is None
    assert d.cause == "none" and d.remedy is None and d.conclusion.startswith("Cause: none")
    # Every double step is the exact step up to rounding (extended precision on).
    for rec in d.steps:
        assert rec["digits"] > 12, rec
        assert not rec["flags"]
    # With the solver's default inexact linear solves (residuals ≤ 1e-4 of the right-hand
    # side) the steps differ from the exact ones by more than rounding, but not by much.
    d = diagnose(rfverify.load("bundled:cube"), tol=1e-10, refine_tol="adaptive", witness_time=0)
    assert d.status == "Solved"
    worst = min(r["digits"] for r in d.steps)
    assert 9 < worst < 15


def test_agreement_is_measured_only_where_the_exact_step_is_defined():
    """v, u and Hr always; r and z only where r is unique (the 16-contact lattice on 4 spheres
    is hyperstatic: H has more kept columns than rows)."""
    d = diagnose(rfverify.load(LATTICE), method="jqinv", tol=1e-10, witness_time=0)
    assert d.evidence["r_unique"] is False and "hyperstatic" in d.evidence["r_unique_note"]
    for rec in d.steps:
        assert math.isnan(rec["digits_r_t"]) and math.isnan(rec["digits_z"])
        assert rec["digits"] == min(rec["digits_v"], rec["digits_u"], rec["digits_Hr"])
    d = diagnose(rfverify.load("bundled:chute"), tol=1e-10, witness_time=0)  # 4 contacts, r unique
    assert d.evidence["r_unique"] is True
    assert all(math.isfinite(rec["digits_r_t"]) and rec["digits"] <= rec["digits_r_t"] for rec in d.steps)


def test_the_threshold_follows_the_forms_conditioning(massratio):
    """threshold = min(−log10 tol, −log10(N·u·κ)), κ = cond(Q_p)² for qp2 (it factors Q_{p²}):
    the same iterate's threshold falls with cond(Q_p) — twice as fast for qp2 as for jqinv."""
    N = massratio.evidence["form_order"]
    for rec in massratio.steps:
        expected = -math.log10(N * 2.0 ** -53) - 2 * math.log10(rec["max_cond_Qp_exact"])
        assert rec["expected"] == pytest.approx(expected)
        assert rec["threshold"] == pytest.approx(min(10.0, expected))
    assert min(r["threshold"] for r in massratio.steps) < 0 < 10 == max(r["threshold"] for r in massratio.steps)
    j = diagnose(rfverify.load(MASSRATIO), method="jqinv", tol=1e-10, witness_time=0, remedies=False)
    assert j.evidence["form_power"] == 1 and massratio.evidence["form_power"] == 2


# ---------------------------------------------------------------------- the cause
def test_a_stall_of_qp2_is_caused_by_precision_shown_by_the_exact_algorithm(massratio):
    """Issue 46's first case: qp2 stalls at 8.8e-6 in double; its steps depart at iteration 6
    (its linear solve stops far above its target, although cond(Q_p) ≈ 3); continued exactly
    from there, the same algorithm meets 1e-10 — so the cause is precision, and it has no λ2
    flag that a cause read off the flags could see."""
    d = massratio
    assert d.status == "InsufficientProgress" and d.cause == "precision"
    assert not d.flagged  # the old diagnosis, from the flags, concluded "not the cause"
    dep = d.evidence["departure"]
    assert dep["iter"] == 6 and dep["digits"] < 6 and "linear solve" in dep["through"]
    run = d.evidence["exact"]
    assert run["start"] == 6 and run["reached_at"] is not None and run["reached_at"] <= 100
    assert run["iterations"][-1]["criterion"] <= 1e-10 < d.steps[-1]["criterion"]
    wit = d.evidence["witness"]  # the mpmath reference on the deciding iterations
    assert wit["step"]["agrees_with_double_double"] > 14 and wit["step"]["double_digits"] < 6
    assert wit["run"]["reached_at"] == run["reached_at"] and wit["run"]["agreement"] > 12
    assert d.conclusion.startswith("Cause: double precision") and "iteration 6" in d.conclusion


def test_a_run_cut_short_by_max_iter_with_healthy_steps_is_not_precision():
    d = diagnose(rfverify.load("bundled:sphere"), tol=1e-10, max_iter=3, witness_time=0)
    assert d.status == "MaxIterations" and d.cause == "iterations"
    assert d.evidence["departure"] is None and d.evidence["shortfall"] is None
    run = d.evidence["exact"]
    assert run["reached_at"] > 3  # the exact algorithm needs more iterations than were given
    assert d.remedy["args"][:2] == ["--method", "jqinv"] and "--max-iter" in d.remedy["args"]
    assert int(d.remedy["args"][d.remedy["args"].index("--max-iter") + 1]) >= run["reached_at"]
    assert d.remedy["status"] == "Solved" and d.remedy["criterion"] <= 1e-10


def test_a_run_that_stalls_only_with_the_default_solves_is_precision(monkeypatch):
    """The run diagnosed is the run as `rfverify solve` makes it.  Where it stalls and the same
    form with every solve refined (the lockstep's run) meets the tolerance, the cause is the
    precision of the linear algebra, not "none".  (Here the plain run is made to refine nothing,
    refine_max=0: qp2 on the 4-contact wedge Chute then ends AlmostSolved at 1.4e-10.)"""
    from rfverify.verify import diagnosis as D

    real = D.solve

    def solve(problem, **kw):
        return real(problem, **kw) if kw.get("keep_iterates") else real(problem, refine_max=0, **kw)

    monkeypatch.setattr(D, "solve", solve)
    d = diagnose(rfverify.load(HARD / "Chute-ndof-24-nc-4-0.hdf5"), method="qp2", tol=1e-10, witness_time=0)
    assert d.status == "AlmostSolved" and d.evidence["lockstep_run"]["status"] == "Solved"
    assert d.cause == "precision" and d.conclusion.startswith("Cause: double precision")
    assert d.remedy is not None and d.remedy["criterion"] <= 1e-10


def test_a_problem_without_a_solution_is_the_data():
    d = diagnose(_infeasible(), tol=1e-10, witness_time=0)
    assert not d.success and d.cause == "data" and d.remedy is None
    assert d.evidence["exact"]["reached_at"] is None
    assert d.evidence["remedies_tried"] and not any(t["reached"] for t in d.evidence["remedies_tried"])
    assert "exact arithmetic does not reach the tolerance either" in " ".join(d.evidence["text"])
    assert d.conclusion.startswith("Cause: the data")


def test_a_stalled_run_names_the_cone_that_held_most_of_its_steps():
    """The evidence lists the run's short steps (as `rfverify solve` runs it) and names the cone
    that held the most of them; recounted here from a run's own trace."""
    problem = _infeasible()
    d = diagnose(problem, tol=1e-10, witness_time=0)
    run = rfverify.solve(problem, method="jqinv", tol=1e-10)
    tr = run.trace
    short = [k for k, a in enumerate(tr["alpha"]) if a < 1]
    assert [h["from_iteration"] for h in d.evidence["steps_held"]] == short and short
    cones = [(int(tr["step_cone"][k]), int(tr["step_side"][k])) for k in short]
    top = max(set(cones), key=lambda c: (cones.count(c), -cones.index(c)))
    most = d.evidence["held_most"]
    assert most["count"] == cones.count(top) and most["short_steps"] == len(short)
    assert most["iterations"] == [k for k, c in zip(short, cones) if c == top]
    lp = rfverify.model.lifting.lift(problem)
    assert (most["contact"], most["side"]) == (int(lp.cone_contact[top[0]]), ("velocity", "reaction")[top[1]])
    assert (f"{len(short)} of the run's steps were cut short by a cone's boundary; contact {most['contact']}'s "
            f"{most['part']} cone ({most['side']}) held {most['count']} of them") in " ".join(d.evidence["text"])


def test_the_cause_follows_the_counterfactual_not_a_constant(monkeypatch):
    """With the continuation's outcome forced, the cause follows it: never reaching → data;
    reaching at once → precision.  (A diagnosis that decided without running it would give the
    same cause in both.)"""
    from rfverify.verify import exact as X

    real = X.ExactAlgorithm.run
    p = rfverify.load(MASSRATIO)

    def never(self, *a, **k):
        out = real(self, *a, **k)
        out.reached_at, out.status = None, rfverify.Status.INSUFFICIENT_PROGRESS
        return out

    monkeypatch.setattr(X.ExactAlgorithm, "run", never)
    assert diagnose(p, method="qp2", witness_time=0, remedies=False).cause == "data"
    monkeypatch.setattr(X.ExactAlgorithm, "run", real)
    assert diagnose(p, method="qp2", witness_time=0, remedies=False).cause == "precision"


def test_tolerance_below_double_reach_is_judged_on_the_exact_point():
    """tol = 1e-25: no float64 answer meets it; the exact continuation is judged on its own
    point (the criterion in mpmath, M symmetrised exactly) and meets it, and the remedy is the
    k-digit path at a tolerance double reaches."""
    d = diagnose(rfverify.load("bundled:chute"), tol=1e-25, max_iter=40, witness_time=0)
    assert d.status != "Solved" and d.cause == "precision"
    assert d.evidence["exact"]["iterations"][-1]["criterion"] <= 1e-25
    assert d.remedy["args"][:2] == ["--digits", "15"] and "--tol" in d.remedy["args"]
    assert d.remedy["status"] == "Certified"


def test_forced_failure_names_iteration_and_cause():
    d = diagnose(rfverify.load("bundled:chute"), tol=1e-25, max_iter=40, witness_time=0, remedies=False)
    assert d.status != "Solved"
    assert "iteration" in d.failure
    flagged = [r for r in d.steps if r["flags"]]
    assert flagged, "the breakdown must be flagged"
    rec = flagged[0]
    assert "≤ 0 in double while exact is" in rec["flags"][0] or "underflowed" in rec["flags"][0]
    # Before the breakdown the agreement degrades as cond(Q_p) grows.
    assert rec["max_cond_Qp"] > 1e15
    early = d.steps[2]
    assert min(early["digits_v"], early["digits_z"]) > 12
    dep = d.evidence["departure"]
    assert dep["iter"] == rec["iter"] and "contact 2 friction (N,T) cone" in dep["through"]


def test_iterate_without_an_exact_step_is_reported(monkeypatch):
    """Where the exact step cannot be taken from the double iterate (not interior in exact
    arithmetic), that iteration has no digits (NaN, null in JSON) and a flag says why; the
    other iterations are diagnosed as usual, and the step before is the departure."""
    from rfverify.verify import exact as X

    real_step = X.ExactAlgorithm.step
    calls = []

    def step(self, start, gamma, rule):
        calls.append(1)
        if len(calls) == 2:
            raise X.ExactStepError("cone 3 is not strictly interior")
        return real_step(self, start, gamma, rule)

    monkeypatch.setattr(X.ExactAlgorithm, "step", step)
    d = diagnose(rfverify.load("bundled:sphere"), tol=1e-10, witness_time=0)
    bad, good = d.steps[1], d.steps[2]
    assert all(math.isnan(bad[k]) for k in ("digits_v", "digits_u", "digits_Hr", "digits"))
    assert math.isnan(bad["min_lam2_z"]["reference"]) and bad["min_lam2_z"]["double"] > 0
    assert bad["flags"] == ["no exact step from the double iterate: cone 3 is not strictly interior"]
    assert good["digits"] > 12 and not good["flags"]
    assert json.loads(rfverify.io.output.dumps(d.to_dict()))["iterations"][1]["digits_v"] is None
    assert d.evidence["departure"]["iter"] == 0


def test_mpmath_is_built_once_and_steps_only_on_the_deciding_iterations(monkeypatch):
    """The lockstep's exact steps are double-double; the mpmath reference is built once and,
    on a healthy run, takes one step: from the iterate whose step agreed least."""
    import reference

    built, steps = [], []

    class Counting(reference.Solver):
        def __init__(self, *a, **k):
            built.append(1)
            super().__init__(*a, **k)

        def step(self, *a, **k):
            steps.append(1)
            return super().step(*a, **k)

    monkeypatch.setattr(reference, "Solver", Counting)
    d = diagnose(rfverify.load("bundled:sphere"), tol=1e-10)
    assert len(d.steps) > 3 and len(built) == 1 and len(steps) == 1
    worst = min(d.steps, key=lambda s: s["digits"])["iter"]
    assert d.evidence["witness"]["step"]["iter"] == worst
    assert d.evidence["witness"]["step"]["agrees_with_double_double"] > 14


# ---------------------------------------------------------------------- remedy and CLI
def test_the_remedy_given_to_rfverify_solve_reaches_the_tolerance(massratio, capsys):
    r = massratio.remedy
    assert r is not None and r["status"] == "Solved" and r["criterion"] <= 1e-10 and r["time"] > 0
    assert r["args"] == ["--method", "jqinv"]
    assert main(["solve", str(MASSRATIO), *r["args"], "--tol", "1e-10"]) == 0
    assert capsys.readouterr().out.startswith("status Solved")


def test_cli_diagnose_exit_code_is_the_double_runs_outcome(capsys):
    """Exit 1 when the double run did not reach --tol (the diagnosis is printed all the same),
    0 when it was Solved; --json does not change that."""
    assert main(["diagnose", "bundled:chute", "--tol", "1e-25", "--max-iter", "40", "--witness-time", "0",
                 "--no-remedy"]) == 1
    out = capsys.readouterr().out
    assert "failure: " in out and "first flagged iteration" in out
    assert main(["diagnose", "bundled:sphere", "--json", "--max-iter", "3", "--witness-time", "0"]) == 1
    s = json.loads(capsys.readouterr().out)
    assert s["status"] == "MaxIterations" and len(s["iterations"]) == 3
    assert s["cause"] == "iterations" and s["remedy"]["status"] == "Solved"
    assert set(s["remedy"]) == {"args", "status", "criterion", "time"} and s["evidence"]["text"]
    assert main(["diagnose", "bundled:sphere", "--json", "--witness-time", "0"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["status"] == "Solved" and s["iterations"] and s["cause"] == "none" and s["remedy"] is None


def test_cli_first_line_states_cause_and_remedy_and_plot_is_written(tmp_path, capsys):
    png = tmp_path / "lockstep.png"
    code = main(["diagnose", str(MASSRATIO), "--method", "qp2", "--quiet", "--witness-time", "0", "--plot", str(png)])
    out = capsys.readouterr().out.splitlines()
    assert code == 1
    assert out[0].startswith("Cause: double precision") and "Remedy: `rfverify solve" in out[0]
    assert f"{MASSRATIO} --method jqinv --tol 1e-10`" in out[0]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20000
    assert any(line.startswith("columns, per step k") for line in out)
    assert any(line.rstrip().endswith("<") or "< " in line for line in out if line[:3].strip().isdigit())


def test_cli_diagnose_reports_progress_on_stderr_only(capsys):
    """Long runs are not silent: one stderr line for the double run, one per exact step, one
    per stage; --json keeps stderr quiet and stdout pure JSON."""
    assert main(["diagnose", "bundled:sphere", "--max-iter", "3", "--witness-time", "0"]) == 1
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert lines[0].startswith("rfverify diagnose: double run (jqinv): MaxIterations after 3 iterations")
    assert [ln for ln in lines if "exact step" in ln] == [f"rfverify diagnose: exact step {k} of 3" for k in (1, 2, 3)]
    assert any("the same algorithm in double-double from iteration" in ln for ln in lines)
    assert any(ln.startswith("rfverify diagnose: remedy: rfverify solve PROBLEM") for ln in lines)
    assert "rfverify diagnose:" not in captured.out  # progress stays off stdout
    assert main(["diagnose", "bundled:sphere", "--max-iter", "3", "--json", "--witness-time", "0"]) == 1
    captured = capsys.readouterr()
    assert captured.err == "" and json.loads(captured.out)["status"] == "MaxIterations"


def test_a_plot_path_that_cannot_be_written_is_refused_before_any_work(tmp_path, capsys):
    assert main(["diagnose", "bundled:sphere", "--plot", str(tmp_path / "no" / "such" / "dir" / "x.png")]) == 2
    captured = capsys.readouterr()
    assert "--plot" in captured.err and "does not exist" in captured.err and "double run" not in captured.err


def test_the_cone_named_is_the_most_frequent_the_first_on_a_tie_and_its_component_is_said():
    from types import SimpleNamespace

    from rfverify.verify.diagnosis import held_most, held_text

    def step(k, contact, part="rolling", side="velocity", **extra):
        return {"from_iteration": k, "alpha": 0.5, "cone": 2 * contact, "contact": contact, "part": part,
                "side": side, **extra}

    run = SimpleNamespace(steps_held=[step(1, 4), step(2, 9), step(5, 9, side="reaction"), step(6, 4), step(8, 9)])
    most = held_most(run)  # 4 and 9 (velocity) twice each, 9 (reaction) once: the first seen, 4
    assert (most["contact"], most["side"], most["count"], most["iterations"], most["short_steps"]) == (
        4, "velocity", 2, [1, 6], 5)
    assert held_text(most, 12) == ["5 of the run's steps were cut short by a cone's boundary; contact 4's rolling "
                                   "cone (velocity) held 2 of them, the first at iteration 1 and the last at "
                                   "iteration 6 (of 12)"]
    split = SimpleNamespace(steps_held=[step(3, 7, component=1), step(4, 7, component=1), step(2, 0, component=0)])
    most = held_most(split)
    assert (most["component"], most["contact"], most["count"]) == (1, 7, 2)
    assert "contact 7's rolling cone (velocity) (component 1) held 2 of them" in held_text(most, 9)[0]
    assert held_most(SimpleNamespace(steps_held=[])) is None and held_text(None, 3) == []


def test_a_local_file_solved_only_on_its_lifting_is_the_data_not_precision():
    """The bundled sphere-from-global's W, as printed, is not positive semidefinite: the run solves
    the lifting (which drops W's negative part) but not the file's own u = W r + q.  The run's own
    arithmetic met the tolerance on the lifting, so "double precision" (what the diagnosis said
    before) was false: the cause is the data, shown by W's own eigenvalues, recomputed here."""
    problem = rfverify.load("bundled:sphere-from-global")
    W = problem.local.W.toarray()
    assert np.linalg.eigvalsh((W + W.T) / 2).min() < -1e-12  # the file's W, as stored
    plain = rfverify.solve(problem, tol=1e-10)
    assert plain.extras["run_verdict"][0] == "Solved" and not plain.success  # the lifting met, the file not
    d = diagnose(problem, tol=1e-10, witness_time=0)
    assert d.cause == "data" and d.evidence["file_only"]["criterion"] == pytest.approx(plain.criterion)
    assert d.conclusion.startswith("Cause: the data, not double precision") and "not positive semidefinite" in \
        d.conclusion
    assert "double precision is the cause" not in " ".join(d.evidence["text"])
    assert d.remedy is None and d.evidence["remedies_tried"]


def test_a_local_file_whose_w_is_positive_semidefinite_is_not_taken_for_one_solved_on_its_lifting_only():
    from rfverify.verify.diagnosis import solved_on_the_lifting_only

    problem = rfverify.load("bundled:sphere")
    res = rfverify.solve(problem, tol=1e-10)
    assert res.success and solved_on_the_lifting_only(problem, res) is None
    stopped = rfverify.solve(problem, tol=1e-10, max_iter=2)  # not met on the lifting either
    assert not stopped.success and solved_on_the_lifting_only(problem, stopped) is None


def test_a_local_file_whose_w_is_not_psd_is_the_data_even_where_the_lifting_is_not_met():
    """At tol 1e-12 the run misses the tolerance on its lifting too, so the file-only case above does
    not apply; the diagnosis said "double precision" (the exact steps run on the file's own W, a
    different, non-convex problem, and met it). The file's criterion of the run's answer is the
    dropped part of W, recomputed here on the lifting (u = Hᵀv + w) and on the file (u = W r + q)."""
    from rfverify.model.measures import measures

    problem = rfverify.load("bundled:sphere-from-global")
    plain = rfverify.solve(problem, tol=1e-12)
    assert plain.extras["run_verdict"][0] != "Solved" and not plain.success
    W = problem.local.W.toarray()
    on_file = measures(problem, plain.v, W @ plain.r + problem.local.q, plain.r, "longdouble").max
    on_lifting = measures(problem, plain.v, problem.H.T @ plain.v + problem.w, plain.r, "longdouble").max
    assert on_file > 1e4 * on_lifting and on_file > 1e-12
    d = diagnose(problem, tol=1e-12, witness_time=0, remedies=False)
    assert d.cause == "data", d.conclusion
    facts = d.evidence["file_only"]
    assert facts["criterion"] == pytest.approx(on_file) and facts["lifting_criterion"] == pytest.approx(on_lifting)
    assert "not convex" in d.conclusion and "double precision is the cause" not in " ".join(d.evidence["text"])
    # the lockstep compares the lifting's steps with the file's: its departure says so
    dep = d.evidence["departure"]
    assert dep is not None and dep["through"].startswith("the lifting, not rounding"), dep
    assert all(s["digits_lifting"] < 12 for s in d.steps if math.isfinite(s["digits"]))


def test_the_lifting_of_a_positive_semidefinite_w_agrees_with_it_to_rounding():
    """The other side of the attribution above: where W is PSD, the lifting agrees with it to what
    float64 holds, so no step of the lockstep is put down to the lifting."""
    d = diagnose(rfverify.load("bundled:sphere"), tol=1e-13, witness_time=0, remedies=False)
    lifting = [s["digits_lifting"] for s in d.steps if math.isfinite(s["digits"])]
    assert lifting and min(lifting) > 15
    assert d.cause == "none" and "file_only" not in d.evidence and d.evidence["departure"] is None


def test_a_witness_with_fewer_digits_than_double_double_is_refused(capsys):
    """A 9-digit witness overruled a double-double continuation that met 1e-25 ("the data") and a
    10-digit one crashed (exit 3): the witness must carry more digits than the steps it checks."""
    from rfverify.errors import InvalidArgumentError

    problem = rfverify.load("bundled:sphere")
    with pytest.raises(InvalidArgumentError, match="dps"):
        diagnose(problem, tol=1e-12, dps=9)
    assert diagnose(problem, tol=1e-12, dps=9, witness_time=0, remedies=False).cause == "none"  # no witness
    with pytest.raises(SystemExit) as stop:
        main(["diagnose", "bundled:sphere", "--dps", "9", "--quiet"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--dps" in err[0] and "34" in err[0]


def test_a_breakdown_of_the_witness_own_linear_algebra_decides_nothing():
    from types import SimpleNamespace

    from rfverify.verify.cause import witnessed_cause
    from rfverify.verify.exact import witness

    class Broken:  # a reference whose step's factorisation fails at its precision
        def iterate(self, *args):
            return SimpleNamespace(r_t=None)

        def step(self, it, gamma, rule):
            raise ArithmeticError("reduced system not positive definite at pivot 4")

    settings = SimpleNamespace(tol=1e-25, sigma_rule="paper")
    w = witness(Broken(), SimpleNamespace(r_t=None), 12, 0.9, settings, lambda it: SimpleNamespace(max=1.0),
                lambda k, it: 30.0, max_steps=5, deadline=math.inf, dps=40)
    assert w.stopped.startswith("its linear algebra broke down at iteration 12") and w.reached_at is None
    assert witnessed_cause("precision", {"run": w.as_dict()}, 40) == "precision"
    # a step the exact algorithm does not have (its point not interior) still decides
    assert witnessed_cause("precision", {"run": {**w.as_dict(), "stopped": "no step from iteration 12: x"}},
                           40) == "data"


def test_a_stall_of_the_default_centring_rule_names_it_with_its_remedy(capsys):
    """MassRatio at mass ratio 1e8 (data/hard/README.md): the default (hybrid) σ rule's steps stall,
    in exact arithmetic too, while the paper's rule solves it.  The diagnosis says the centring
    rule, not just "the data", and its remedy, given to `rfverify solve`, is Solved."""
    path = HARD / "MassRatio-1e8-ndof-600-nc-297-1.hdf5"
    d = diagnose(rfverify.load(path), tol=1e-10, witness_time=0)
    assert d.status == "InsufficientProgress" and d.cause == "data"
    assert d.remedy["args"][-2:] == ["--sigma-rule", "paper"] and d.remedy["status"] == "Solved"
    assert d.conclusion.startswith("Cause: the centring rule on these data, not double precision")
    assert main(["solve", str(path), *d.remedy["args"], "--tol", "1e-10", "--quiet"]) == 0
    assert main(["solve", str(path), "--method", "jqinv", "--quiet"]) == 1  # the default rule: not Solved
    assert main(["solve", str(path), "--quiet"]) == 0  # auto's last resort is the remedy (test_solver.py)
    capsys.readouterr()
    assert main(["solve", str(path), "--sigma-rule", "paper", "--method", "clarabel"]) == 2
    assert "--sigma-rule: is Algorithm 1's centring rule" in capsys.readouterr().err


def test_the_time_limit_bounds_the_diagnosed_run_and_the_exit_code_is_that_runs(monkeypatch, capsys):
    """Audit (2026-12-08): the diagnosed run itself was not given --time-limit (a 2800-contact bed
    ran 23 s under --time-limit 3), and the exit code followed the diagnosis's status (MaxTime
    when a later stage was cut short) where the help says it is the double run's outcome."""
    import time

    import rfverify.verify.diagnosis as diagnosis

    real = diagnosis.solve
    calls = []

    def solve_then_wait(*a, **k):
        calls.append(k.get("time_limit"))
        out = real(*a, **k)
        time.sleep(2.5 if len(calls) == 2 else 0)  # the limit runs out after the lockstep's run
        return out

    monkeypatch.setattr(diagnosis, "solve", solve_then_wait)
    code = main(["diagnose", "bundled:chute", "--time-limit", "2", "--witness-time", "0", "--no-remedy", "--json"])
    d = json.loads(capsys.readouterr().out)
    assert calls[0] == 2  # the diagnosed run gets the user's limit, as named
    assert d["evidence"]["run"]["status"] == "Solved" and d["status"] == "MaxTime"
    assert code == 0
