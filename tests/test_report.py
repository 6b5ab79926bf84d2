"""The report's aggregation and its lockstep diagnosis of exactly what the bench ran: the
component sub-problem reproduces the solver's own component run, worst cases put failures
first, the work–precision median counts every problem, and one median everywhere."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import scipy
import scipy.sparse as sp

from rfverify import Problem, solve
from rfverify.scenes.random_problems import random_problem
from rfverify.report.aggregates import median, worst_cases
from rfverify.report.data import RunData
from rfverify.report.figures import work_precision_medians
from rfverify.report.lockstep import component_problem, diagnose_as_run, solve_groups
from rfverify.solver import Settings


@pytest.fixture(scope="module")
def two_bodies_problem():
    """Two independent random problems side by side: the solver splits it into components."""
    a = random_problem(6, 10, seed=3)
    b = random_problem(5, 8, seed=4, mass_ratio=1e3)
    return Problem.from_arrays(sp.block_diag([a.M, b.M]), sp.block_diag([a.H, b.H]), np.r_[a.f, b.f],
                               np.r_[a.w, b.w], np.r_[a.mu, b.mu], np.r_[a.mu_r, b.mu_r])


@pytest.mark.parametrize("method", ["jqinv", "qp2"])
def test_component_subproblem_is_the_run_the_solver_made(two_bodies_problem, method):
    """Solved alone, each component's sub-problem takes exactly the iterates the split solve
    took for it (status, iterations and μ of every iteration, bit for bit)."""
    p = two_bodies_problem
    settings = Settings(tol=1e-10)
    lp, groups = solve_groups(p, settings)
    whole = solve(p, method=method, tol=1e-10)
    runs = whole.extras["component_runs"]
    assert len(groups) == len(runs) >= 2
    for group, run in zip(groups, runs):
        sub, contacts = component_problem(p, lp, group)
        assert sub.n_contacts == contacts.size and sub.n_dofs == group[0].size
        alone = solve(sub, method=method, tol=1e-10, split_components=False)
        assert alone.status == run["status"] and alone.nit == run["nit"]
        assert np.array_equal(np.asarray(alone.trace["mu"]), np.asarray(run["trace"]["mu"]))


def test_diagnosis_of_a_split_run_diagnoses_its_failing_component(two_bodies_problem):
    """With 4 iterations every component stops at MaxIterations: the diagnosis is of the
    first failing component alone, says so, and ends as it did inside the split run."""
    diag = diagnose_as_run(two_bodies_problem, "jqinv", 1e-10, max_iter=4, dps=34, bench_status="MaxIterations")
    scope = diag["scope"]
    assert scope["mode"] == "component" and scope["index"] == 0 and scope["count"] == 2
    assert scope["reproduced"] and scope["status"] == diag["status"] == "MaxIterations" and diag["nit"] == 4
    assert "component 1 of 2 alone" in scope["text"] and "note" not in scope["text"]
    assert len(diag["iterations"]) == diag["nit"]  # one exact step per iteration, from the start point on


def test_diagnosis_says_when_every_component_met_the_tolerance(two_bodies_problem):
    diag = diagnose_as_run(two_bodies_problem, "jqinv", 1e-8, max_iter=100, dps=34, bench_status="Solved")
    assert diag["scope"]["mode"] == "unsplit" and "diagnosed without splitting" in diag["scope"]["text"]


def _fake(runs: list[dict]) -> RunData:
    keys = sorted({r["problem"] for r in runs})
    problems = {k: {"key": k, "collection": "c", "n_contacts": 3, "n_dofs": 6, "sha256": ""} for k in keys}
    data = RunData(Path("."), {}, problems)
    for r in runs:
        data.solves.append({"kind": "solve", "time": 1.0, "nit": 10, **r})
    data.build_index()
    return data


def test_worst_cases_put_refuted_claims_then_failures_before_solved_runs():
    data = _fake([
        {"problem": "hard", "method": "jqinv", "tol": 1e-10, "solved": True, "status": "Solved",
         "max_cond_Qp": 1e15, "refuted": False},
        {"problem": "failed", "method": "qp2", "tol": 1e-8, "solved": False, "status": "InsufficientProgress",
         "max_cond_Qp": 1e3, "refuted": False},
        {"problem": "lied", "method": "reduced", "tol": 1e-8, "solved": False, "status": "Solved",
         "max_cond_Qp": 1e2, "refuted": True},
        {"problem": "peer", "method": "clarabel", "tol": 1e-10, "solved": False, "status": "Solved",
         "refuted": True},                      # no Algorithm 1 iterates: nothing to lockstep
        {"problem": "slow", "method": "jqinv", "tol": 1e-10, "solved": False, "status": "Timeout",
         "refuted": False},                     # not rerun in lockstep
    ])
    chosen = worst_cases(data, 5, 40)
    assert [c["problem"] for c in chosen] == ["lied", "failed", "hard"]
    assert "refuted" in chosen[0]["why"] and "not verified solved" in chosen[1]["why"]
    assert "no failed run left" in chosen[2]["why"]
    assert [c["problem"] for c in worst_cases(data, 1, 40)] == ["lied"]


def test_work_precision_median_counts_every_problem():
    """A method that reaches 12 digits on one problem of three and nothing on the others has a
    median of 0 digits, not 12 (the old 'median over problems that reach k' showed 12)."""
    keys = ["p1", "p2", "p3"]
    series = {"lucky": {"p1": [(0.1, 3.0), (0.2, 12.0)]},
              "steady": {k: [(0.1, 2.0), (0.3, 6.0), (0.4, 5.0)] for k in keys}}
    grid, med = work_precision_medians(keys, series, grid=[0.05, 0.15, 0.25, 0.35, 1.0])
    assert med["lucky"].tolist() == [0, 0, 0, 0, 0]
    assert med["steady"].tolist() == [0, 2, 2, 6, 6]  # best so far: 5 at 0.4 s does not undo 6


def test_one_median():
    assert median([4.0, 1.0, 3.0, 2.0]) == 2.5          # the mean of the middle two, like np.median
    assert median([1.0, None, float("nan"), 3.0]) == 2.0
    assert median([1.0, math.inf, math.inf]) == math.inf
    assert median([None]) is None


def test_report_of_algorithm1_forms_only_without_trajectories(tmp_path, capsys):
    """A bench of one Algorithm 1 form, no trajectories and no k-digit path, has no line to
    draw in the work–precision figure: the report is still written (it once crashed on an
    empty legend, exit 3)."""
    from rfverify.cli import main

    run = tmp_path / "run"
    assert main(["bench", "bundled:sphere", "--methods", "jqinv", "--tol", "1e-8", "--digits", "0",
                 "--no-trajectories", "--out", str(run), "--quiet"]) == 0
    assert main(["report", str(run), "--quiet"]) == 0
    assert "internal error" not in capsys.readouterr().err
    assert any(run.rglob("*.html"))
    # The versions of the libraries whose builds change results are recorded and shown.
    machine = json.loads((run / "manifest.json").read_text())["machine"]
    assert machine["scipy"] == scipy.__version__ and "qdldl" in machine and "clarabel" in machine
    summary = (run / "summary.md").read_text()
    assert f"scipy {scipy.__version__}" in summary


def test_the_first_screen_answers_in_plain_words(tmp_path):
    """Issue 39: the first screen says, in sentences, which method gives k proven digits on which
    problems, names the problems it did not prove with a reason and a next step, says where
    double precision stops, and defines its terms."""
    from rfverify.cli import main

    run = tmp_path / "run"
    assert main(["bench", "bundled:sphere", "bundled:cube", "--methods", "jqinv,clarabel", "--tol", "1e-8",
                 "--no-trajectories", "--out", str(run), "--quiet"]) == 0
    assert main(["report", str(run), "--quiet"]) == 0
    summary = (run / "summary.md").read_text()
    first = summary.split("## At a glance", 1)[1].split("![", 1)[0]
    assert first.strip().startswith("In short: for 10 proven digits use the 10-digit path")
    assert "it proved 1 of 2 problems" in first
    assert "The 1 it did not: bundled/cube, its W is indefinite as stored" in first
    assert "certify the global problem it was made from instead" in first
    assert "Terms: v are the bodies' velocities" in first


def _clustered_run() -> RunData:
    """Five methods whose median (time, digits) per tolerance lie close together, as on the
    committed example report, where the tolerance labels once overlapped."""
    rng = np.random.default_rng(1)
    keys = [f"p{i}" for i in range(12)]
    problems = {k: {"key": k, "collection": "c", "n_contacts": 3, "n_dofs": 6, "sha256": ""} for k in keys}
    data = RunData(Path("."), {"digits": 10}, problems)
    for m, base in (("jqinv", 0.14), ("qp2", 0.15), ("reduced", 0.145), ("noscaling", 0.16), ("clarabel", 0.025)):
        for tol, digits in ((1e-8, 6.0), (1e-9, 6.6), (1e-10, 7.0)):
            for k in keys:
                data.solves.append({"kind": "solve", "problem": k, "method": m, "tol": tol, "nit": 10,
                                    "time": base * (1 + 0.02 * rng.standard_normal()), "solved": True,
                                    "status": "Solved", "proven": {"answer": digits + 0.3 * rng.standard_normal()}})
    data.build_index()
    return data


def _boxes(texts):
    from matplotlib.text import Text

    return [Text.get_window_extent(t) for t in texts]


def _overlapping(boxes):
    return [(i, j) for i in range(len(boxes)) for j in range(i) if boxes[i].overlaps(boxes[j])]


def test_tolerance_labels_of_the_first_figure_do_not_overlap(tmp_path, monkeypatch):
    """Issue 49: in proven_digits.png no two tolerance labels overlap, none leaves the axes, and
    each still names a median of its own method (its colour) — on medians crowded together."""
    from matplotlib.text import Annotation

    from rfverify.report import figures

    drawn = {}
    save = figures._save

    def keep(fig, path):  # the figure as it is saved (the boxes measured before savefig closes it)
        fig.canvas.draw()
        drawn["labels"] = [(t.get_text(), t.get_color()) for t in fig.axes[0].texts if isinstance(t, Annotation)]
        drawn["boxes"] = _boxes(t for t in fig.axes[0].texts if isinstance(t, Annotation))
        drawn["frame"] = fig.axes[0].get_window_extent().frozen()
        save(fig, path)

    monkeypatch.setattr(figures, "_save", keep)
    assert figures.proven_digits_time(_clustered_run(), tmp_path) == tmp_path / "proven_digits.png"
    colours = {m: figures._style(m)[0] for m in ("jqinv", "qp2", "reduced", "noscaling", "clarabel")}
    assert sorted(drawn["labels"]) == sorted((t, c) for c in colours.values() for t in ("1e-08", "1e-09", "1e-10"))
    boxes = drawn["boxes"]
    assert not _overlapping(boxes)
    assert all(drawn["frame"].contains(b.x0, b.y0) and drawn["frame"].contains(b.x1, b.y1) for b in boxes)


def test_labels_apart_moves_what_a_fixed_offset_would_stack():
    """The same labels at one fixed offset (the old drawing) overlap; placed apart they do not,
    and none covers another labelled point."""
    from rfverify.report.figures import _plt, labels_apart

    plt = _plt()
    items = [(0.15 + 0.001 * i, 6.0 + 0.05 * i, f"1e-{8 + i % 3:02d}", "C0") for i in range(9)]
    fig, ax = plt.subplots(figsize=(4, 3))
    ax.set_xlim(0.1, 0.2)
    ax.set_ylim(0, 10)
    fixed = [ax.annotate(t, (x, y), textcoords="offset points", xytext=(4, 3), fontsize=6) for x, y, t, _ in items]
    fig.canvas.draw()
    assert _overlapping(_boxes(fixed))
    for t in fixed:
        t.remove()
    placed = labels_apart(ax, items)
    fig.canvas.draw()
    boxes = _boxes(placed)
    assert not _overlapping(boxes)
    points = [ax.transData.transform((x, y)) for x, y, _, _ in items]
    for i, b in enumerate(boxes):
        assert not any(b.contains(px, py) for j, (px, py) in enumerate(points) if j != i)
    plt.close(fig)
