"""The bench runner and the report: verified counting, resume, time limits, profiles, and
summary counts that agree with an independent recheck of the saved solutions."""

from __future__ import annotations

import base64
import json
import math
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from rfverify import load, solve
from rfverify.bench import HighPrecisionChecker, run_bench
from rfverify.bench.runner import BenchInputError, discover_problems
from rfverify.model.measures import measures
from rfverify.cli import main
from rfverify.scenes.random_problems import random_problem
from rfverify.report import load_run, make_report
from rfverify.report.aggregates import performance_profile, sgm
from rfverify.report.data import RunData
from rfverify.report.document import FEW_PROBLEMS


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    coll = out / "gen"
    coll.mkdir()
    from rfverify.io import save

    save(random_problem(6, 10, seed=3, mu_r_zero_fraction=0.3), coll / "rand-a.hdf5")
    save(random_problem(5, 8, seed=4, mass_ratio=1e3), coll / "rand-b.hdf5")
    summary = run_bench(["bundled:sphere", "bundled:chute", str(coll)], out / "run",
                        methods=("jqinv", "qp2", "clarabel"), tols=(1e-8, 1e-10), jobs=2,
                        digits=10, reference_max_contacts=12, quiet=True)
    return out / "run", summary


def test_every_task_has_a_record(run_dir):
    path, summary = run_dir
    # 4 problems × 3 methods × 2 tols + 4 × 2 trajectories + 4 digits paths (all ≤ 12 contacts)
    assert summary["total"] == 24 + 8 + 4
    assert summary["ran"] == summary["total"] and summary["timeouts"] == 0
    records = list((path / "runs").rglob("*.json"))
    assert len(records) == summary["total"]
    for rec in map(lambda p: json.loads(p.read_text()), records):
        assert rec["complete"] and "status" in rec and "path" not in rec  # no machine-local path


def test_resume_skips_finished_runs(run_dir):
    path, _ = run_dir
    again = run_bench(["bundled:sphere", "bundled:chute", str(path.parent / "gen")], path,
                      methods=("jqinv", "qp2", "clarabel"), tols=(1e-8, 1e-10), jobs=2,
                      digits=10, reference_max_contacts=12, quiet=True)
    assert again["ran"] == 0 and again["skipped"] == again["total"]


def test_solved_means_independently_verified(run_dir):
    path, _ = run_dir
    data = load_run(path)
    for rec in data.solves:
        problem = load(_problem_path(data, rec["problem"]))
        with np.load(rec["_npz"]) as z:
            v, u, r = z["v"], z["u"], z["r"]
        # A different code path (longdouble numpy) must agree with the 30-digit verdict.
        ld = measures(problem, v, u, r, "longdouble").max
        assert rec["solved"] == (rec["verified"]["max"] <= rec["tol"])
        if abs(math.log10(max(ld, 1e-300)) - math.log10(rec["tol"])) > 0.1:  # not a borderline case
            assert rec["solved"] == (ld <= rec["tol"]), rec["problem"]


def test_summary_counts_agree_with_recheck_of_saved_solutions(run_dir):
    path, _ = run_dir
    make_report(path, diagnose_count=1, diagnose_max_contacts=4)
    text = (path / "summary.md").read_text()
    rows = re.findall(r"^\| all \| (\w+) \| ([0-9e.+-]+) \| (\d+)/(\d+) \|", text, re.M)
    assert len(rows) == 6
    data = load_run(path)
    for method, tol, solved, total in rows:
        recheck = 0
        recs = [r for r in data.solves if r["method"] == method and math.isclose(r["tol"], float(tol))]
        for rec in recs:
            problem = load(_problem_path(data, rec["problem"]))
            with np.load(rec["_npz"]) as z:
                recheck += HighPrecisionChecker(problem, dps=40).criterion(z["v"], z["u"], z["r"])["max"] <= rec["tol"]
        assert (int(solved), int(total)) == (recheck, len(recs)), (method, tol)


class _Links(HTMLParser):
    """Every attribute of report.html that makes a browser load or link something, and the
    embedded images in order."""

    def __init__(self):
        super().__init__()
        self.links, self.images = [], []

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if name in ("src", "href", "srcset", "data", "poster", "action", "background") or (
                    name == "style" and "url(" in (value or "")):
                self.links.append((tag, name, value))
            if tag == "img" and name == "src":
                self.images.append(value)


def _embedded_png(src: str) -> bytes:
    head, data = src.split(",", 1)
    assert head == "data:image/png;base64"
    return base64.b64decode(data, validate=True)


def test_report_files_and_figures(run_dir):
    path, _ = run_dir
    make_report(path, diagnose_count=1, diagnose_max_contacts=4)
    page = (path / "report.html").read_text()
    parser = _Links()
    parser.feed(page)
    # Issue 49: report.html stands alone: nothing it loads or links is a local file.
    local = [link for link in parser.links if not re.match(r"(data:|https?://)", link[2] or "")]
    assert not local, local
    assert "url(" not in page.split("<style>", 1)[1].split("</style>", 1)[0]
    # Its figures are the PNG files written beside it (summary.md links those), embedded.
    summary = (path / "summary.md").read_text()
    linked = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", summary)
    assert {"profile_time.png", "profile_iterations.png", "work_precision.png", "proven_digits.png",
            "hard_per_family.png"} <= set(linked)
    assert [_embedded_png(src) for src in parser.images] == [(path / name).read_bytes() for name in linked]
    for name in linked:
        png = path / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    # The first screen has one figure: proven digits against time.
    glance = _Links()
    glance.feed(page.split("id='glance'", 1)[1].split("<h2", 1)[0])
    assert [_embedded_png(src) for src in glance.images] == [(path / "proven_digits.png").read_bytes()]
    for heading in ("At a glance", "Robustness: solved per collection", "Speed on common solved sets",
                    "Performance profiles", "How far double precision gets", "What 10 proven digits cost",
                    "Per-iteration diagnostics", "Failures and their diagnosed causes", "Refuted claims",
                    "cond(Q_p) and λ2 per iteration, one hard problem per family"):
        assert f"## {heading}" in summary
    # Tables say yes/no/– instead of Python's True/False/None.
    assert not re.search(r"\| (True|False|None) \|", summary)
    # A Clarabel claim the recheck refutes is shown with the measure that refuted it.
    assert re.search(r"\| clarabel \| Solved \(refuted: \w+ [0-9.e+-]+", summary)
    # The lockstep diagnosis is cached.
    assert list((path / "diagnostics").glob("*.json"))


def test_work_precision_uses_reference_digits(run_dir):
    path, _ = run_dir
    data = load_run(path)
    assert set(data.references) == set(data.problems)  # all ≤ 12 contacts
    for t in data.trajectories:
        digs = [d for d in t["digits_v_iterates"] if d is not None]
        assert len(digs) == len(t["iterates"]) and digs[0] < max(digs)  # from a start that is not the answer
        if t["method"] == "jqinv":
            assert max(digs) > 6, t["problem"]   # (qp2 stalls near 1e-6 on the stiff rand-b)
    for d in data.digits.values():
        assert d["certified"], d["message"]


def test_time_limit_kills_and_records(tmp_path):
    out = run_bench(["bundled:chute"], tmp_path / "run", methods=("jqinv",), tols=(1e-10,),
                    trajectories=False, digits=0, time_limit=1e-3, quiet=True)
    assert out["timeouts"] == 1
    rec = json.loads(next((tmp_path / "run" / "runs").rglob("*.json")).read_text())
    assert rec["status"] == "Timeout" and rec["solved"] is False
    # A timed-out run is not "finished" for the next invocation's purposes? It is: resume
    # must not loop forever on a problem that always times out.
    again = run_bench(["bundled:chute"], tmp_path / "run", methods=("jqinv",), tols=(1e-10,),
                      trajectories=False, digits=0, time_limit=1e-3, quiet=True)
    assert again["ran"] == 0


def test_changed_problem_file_is_rerun(tmp_path):
    from rfverify.io import save

    coll = tmp_path / "c"
    coll.mkdir()
    save(random_problem(3, 4, seed=1), coll / "p.hdf5")
    kw = dict(methods=("jqinv",), tols=(1e-8,), trajectories=False, digits=0, quiet=True)
    assert run_bench([str(coll)], tmp_path / "run", **kw)["ran"] == 1
    save(random_problem(3, 4, seed=2), coll / "p.hdf5")
    assert run_bench([str(coll)], tmp_path / "run", **kw)["ran"] == 1


def test_checker_rejects_a_perturbed_solution():
    problem = random_problem(4, 6, seed=7)
    res = solve(problem, tol=1e-12)
    checker = HighPrecisionChecker(problem)
    good = checker.criterion(res.v, res.u, res.r)
    assert good["max"] <= 1e-11
    v = res.v.copy()
    v[0] *= 1 + 1e-6
    bad = checker.criterion(v, res.u, res.r)
    assert bad["max"] > 1e-9 and bad["dynamics"] > 1e-9
    nan = checker.criterion(np.full_like(v, np.nan), res.u, res.r)
    assert not nan["finite"] and nan["max"] == math.inf
    with pytest.raises(ValueError, match="shapes"):
        checker.criterion(v[:-1], res.u, res.r)


def _fake(times: dict) -> RunData:
    problems = {k: {"key": k, "collection": "c", "n_contacts": 1, "n_dofs": 6, "sha256": ""} for k in times}
    data = RunData(Path("."), {}, problems)
    for k, per in times.items():
        for m, t in per.items():
            data.solves.append({"problem": k, "method": m, "tol": 1e-8, "time": t, "nit": 10,
                                "solved": math.isfinite(t)})
    data.build_index()
    return data


def test_performance_profile_definition():
    data = _fake({"p1": {"jqinv": 1.0, "clarabel": 2.0},
                  "p2": {"jqinv": 3.0, "clarabel": 1.0},
                  "p3": {"jqinv": 4.0, "clarabel": math.inf},
                  "p4": {"jqinv": math.inf, "clarabel": math.inf}})
    taus, prof = performance_profile(data, 1e-8)

    def rho(method, tau):
        return prof[method][np.searchsorted(taus, tau, side="right") - 1]

    assert rho("jqinv", 1.0) == 0.5 and rho("clarabel", 1.0) == 0.25
    assert rho("clarabel", 2.0) == 0.5
    assert rho("jqinv", 3.0) == 0.75     # never 1: p4 is solved by no method
    assert max(prof["clarabel"]) == 0.5


def test_shifted_geometric_mean():
    assert sgm([1.0, 1.0], shift=0.0) == pytest.approx(1.0)
    assert sgm([1.0, 4.0], shift=0.0) == pytest.approx(2.0)
    assert sgm([0.0, 0.0], shift=0.01) == pytest.approx(0.0, abs=1e-15)
    assert math.isnan(sgm([]))


def test_discover_rejects_bad_inputs(tmp_path):
    with pytest.raises(BenchInputError, match="no such file"):
        discover_problems([str(tmp_path / "missing")])
    (tmp_path / "empty").mkdir()
    with pytest.raises(BenchInputError, match="no problem files"):
        discover_problems([str(tmp_path / "empty")])
    with pytest.raises(BenchInputError, match="same problem key"):
        discover_problems(["bundled:chute", "bundled:chute"])


def test_cli_bench_and_report_errors(tmp_path, capsys):
    assert main(["bench", str(tmp_path / "nope"), "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no such file" in err
    with pytest.raises(SystemExit) as exc:
        main(["bench", "bundled", "--methods", "fast", "--out", str(tmp_path / "r")])
    assert exc.value.code == 2
    assert main(["report", str(tmp_path)]) == 2
    assert "not a bench run directory" in capsys.readouterr().err


def test_cli_bench_json(tmp_path, capsys):
    rc = main(["bench", "bundled:sphere", "--methods", "jqinv", "--tol", "1e-9", "--digits", "0",
               "--no-trajectories", "--out", str(tmp_path / "r"), "--quiet", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert out["counts"] == [{"method": "jqinv", "tol": 1e-9, "solved": 1, "total": 1}]


def _problem_path(data, key):
    from rfverify.bench.runner import resolve_spec

    return resolve_spec(data.problems[key]["spec"], data.run_dir)


def test_progress_fraction_lines_off_a_terminal():
    import io

    from rfverify.progress import Progress

    out = io.StringIO()  # not a TTY: one line per completed tenth, none for smaller steps
    bar = Progress(100, "gen", stream=out)
    for frac in (0.02, 0.05, 0.12, 0.15, 0.19, 0.31, 1.0, 1.0):
        bar.update_fraction(frac, "x")
    bar.close()
    lines = out.getvalue().splitlines()
    assert [ln.split()[1] for ln in lines] == ["[12/100]", "[31/100]", "[100/100]"]
    quiet = io.StringIO()
    Progress(100, "gen", stream=quiet, quiet=True).update_fraction(0.5)
    assert quiet.getvalue() == ""


# ---------------------------------------------------------------------- the report's first screen
def _md_tables(text: str) -> list[tuple[list, list]]:
    """Every Markdown table of ``text`` as (header, rows of cells)."""
    tables, lines = [], text.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].startswith("| ") and i + 1 < len(lines) and lines[i + 1].startswith("|---"):
            header = [c.strip() for c in lines[i].strip("|").split(" | ")]
            rows, i = [], i + 2
            while i < len(lines) and lines[i].startswith("| "):
                rows.append([c.strip() for c in lines[i].strip().strip("|").split(" | ")])
                i += 1
            tables.append((header, rows))
        else:
            i += 1
    return tables


def _table_with(text: str, first_header: str, *columns) -> tuple[list, list]:
    for header, rows in _md_tables(text):
        if header[0] == first_header and all(any(c in h for h in header) for c in columns):
            return header, rows
    raise AssertionError(f"no table with {first_header!r} and {columns}")


def _section(text: str, heading: str) -> str:
    start = text.index(f"## {heading}")
    end = text.find("\n## ", start + 3)
    return text[start:end if end >= 0 else len(text)]


def _records(path: Path, kind: str) -> list[dict]:
    recs = [json.loads(p.read_text()) for p in (path / "runs").rglob("*.json")]
    return [r for r in recs if r["kind"] == kind]


def test_glance_numbers_agree_with_the_tables_below(run_dir):
    """The four answers of the first screen are the numbers of the tables under it: same sets,
    same median, same formatting; the cost of proven digits is recomputed from the records."""
    path, _ = run_dir
    make_report(path, diagnose_count=1, diagnose_max_contacts=4)
    text = (path / "summary.md").read_text()
    glance = _section(text, "At a glance")

    # Fastest: the SGM time pivot table of "Speed on common solved sets".
    speed = _section(text, "Speed on common solved sets")
    header, rows = _table_with(speed.split("SGM iterations")[0], "method", "A1 common")
    cell = {(r[0], h): c for r in rows for h, c in zip(header[1:], r[1:])}
    a1_forms = [r[0] for r in rows if r[0] != "clarabel"]
    few = r"(, too few to rank by)?"
    lines = re.findall(r"tol (\S+): Algorithm 1 form (\w+), (\S+) s on the (\d+) problems? every form solved" + few
                       + r"(?: \(([^)]*)\))?; overall (\w+), (\S+) s on the (\d+) problems? every method solved" + few,
                       glance)
    assert len(lines) == 2, glance
    for tol, form, t_form, n_a1, few_a1, others, best, t_best, n_all, few_all in lines:
        # Issue 49: a ranking on fewer than FEW_PROBLEMS problems says they are too few.
        assert bool(few_a1) == (int(n_a1) < FEW_PROBLEMS) and bool(few_all) == (int(n_all) < FEW_PROBLEMS)
        col_a1 = next(h for h in header if h.startswith(f"{tol} A1 common (n={n_a1})"))
        col_all = next(h for h in header if h.startswith(f"{tol} all common (n={n_all})"))
        times_a1 = {m: float(cell[(m, col_a1)]) for m in a1_forms}
        assert cell[(form, col_a1)] == t_form and times_a1[form] == min(times_a1.values())
        for m, t in re.findall(r"(\w+) (\S+) s", others or ""):
            assert cell[(m, col_a1)] == t
        times_all = {r[0]: float(cell[(r[0], col_all)]) for r in rows}
        assert cell[(best, col_all)] == t_best and times_all[best] == min(times_all.values())

    # Most robust: the "all" rows of the robustness table.
    robust = re.findall(r"tol (\S+): ([\w, ]+) \((\d+)/(\d+) verified\)(?:; (?!on the)((?:(?!; on the).)*))?"
                        r"(; on the \d+ problems?, too few to rank by)?$", glance, re.M)
    assert len(robust) == 2
    rows = [r for r in _table_with(text, "collection", "solved", "refuted claims")[1] if r[0] == "all"]
    for tol, best, top, total, rest, few in robust:
        assert bool(few) == (int(total) < FEW_PROBLEMS)
        solved = {r[1]: int(r[3].split("/")[0]) for r in rows if r[2] == tol}
        assert max(solved.values()) == int(top) and {r[3].split("/")[1] for r in rows if r[2] == tol} == {total}
        assert set(best.split(", ")) == {m for m, k in solved.items() if k == int(top)}
        assert {m: int(k) for m, k in re.findall(r"(\w+) (\d+)", rest or "")} == \
            {m: k for m, k in solved.items() if k != int(top)}

    # How far double precision gets, per form: its summary table.
    per_form = re.findall(r"- (\w+): (\S+) digits of v \((\d+) reached on (\d+)/(\d+)\), best criterion (\S+)", glance)
    assert {m for m, *_ in per_form} == {"jqinv", "qp2"}
    header, rows = _table_with(_section(text, "How far double precision gets"), "method", "median best digits of v")
    table = {r[0]: dict(zip(header, r)) for r in rows}
    for m, digs, target, reached, n, crit in per_form:
        assert table[m]["median best digits of v"] == digs
        assert table[m]["median best verified criterion"] == crit
        assert table[m][f"reach {target} digits"] == f"{reached}/{n}"

    # 10 proven digits cost: recomputed from the records (total path time; ratio to the
    # bench's jqinv solve at the loosest tolerance ≤ 1e-10, here 1e-10), numpy's median.
    got = re.search(r"\*\*10 proven digits cost\*\* (\S+) s \((\S+)× the double solve\) — median over the (\d+) "
                    r"of (\d+) problems", glance)
    assert got, glance
    digits = {r["problem"]: r for r in _record_files(path, "digits")}
    solves = {(r["problem"], r["method"], r["tol"]): r for r in _record_files(path, "solve")}
    cert = [d for d in digits.values() if d["certified"]]
    times = [d["time"] for d in cert]
    ratios = [d["time"] / solves[(d["problem"], "jqinv", 1e-10)]["time"] for d in cert]
    assert (int(got[3]), int(got[4])) == (len(cert), len(digits))
    assert got[1] == format(float(np.median(times)), ".3g")
    assert got[2] == format(float(np.median(ratios)), ".1f")
    paragraph = _section(text, "What 10 proven digits cost")
    assert f"path time {got[1]} s; ratio {got[2]}×" in paragraph


def _record_files(path: Path, kind: str) -> list[dict]:
    return _records(path, kind)


def test_refuted_claims_equal_an_independent_recount_of_the_records(run_dir):
    """Every saved solve whose solver itself said Solved or AlmostSolved and whose recheck's
    criterion exceeds the tolerance that claim asserts — recounted here from the JSON files,
    without the report's code — is what the glance and the tables count."""
    path, _ = run_dir
    make_report(path, diagnose_count=1, diagnose_max_contacts=4)
    recount = 0
    for rec in _records(path, "solve"):
        crit = rec["verified"]["max"]
        crit = math.inf if crit is None else crit
        own = rec["solver_status_own"]  # the solver's own word (Clarabel's status for clarabel)
        assert rec["claim"] == (own if own in ("Solved", "AlmostSolved") else None)
        if rec["claim"] == "Solved":
            assert rec["claim_tol"] == rec["tol"]
        false = rec["claim"] in ("Solved", "AlmostSolved") and not crit <= rec["claim_tol"]
        assert rec["refuted"] == false, rec["problem"]
        recount += false
    assert recount > 0  # the fixture has Clarabel answers the recheck refutes
    text = (path / "summary.md").read_text()
    got = re.search(r"\*\*Refuted claims:\*\* (\d+) run\(s\)", text)
    assert got and int(got[1]) == recount
    rows = [r for r in _table_with(text, "collection", "refuted claims")[1] if r[0] == "all"]
    assert sum(int(r[4]) for r in rows) == recount
    # Grouped, once: the refuted-claims table counts each, the failures table none of them.
    fail_rows = [r for h, rows in _md_tables(_section(text, "Failures and their diagnosed causes"))
                 if h[0] == "problem" for r in rows]
    refuted = {(r["problem"], r["method"], format(r["tol"], "g")) for r in _records(path, "solve") if r["refuted"]}
    assert not refuted & {tuple(r[:3]) for r in fail_rows}
    header, groups = _table_with(_section(text, "Refuted claims"), "method", "shown as", "runs")
    assert sum(int(g[2]) for g in groups) == recount
    # Each refuted run's label, recomputed from its record: its claim and its worst recheck measure.
    from rfverify.model.measures import CRITERION

    examples = " ".join(g[5] for g in groups)
    for rec in _records(path, "solve"):
        if rec["refuted"]:
            ver = rec["verified"]
            worst = max((k for k in CRITERION if ver.get(k) is not None), key=lambda k: ver[k])
            label = f"{rec['claim']} (refuted: {worst} {ver[worst]:.1e})"
            assert f"{rec['problem']} at {rec['tol']:g}: {label}" in examples, (label, examples)


def test_every_answer_gets_its_proven_digits_from_the_proof(run_dir):
    """Every saved answer of every method (the peer included) has proven digits, and they are what
    certify proves of it at the problem's proven point (saved by the digits task)."""
    import rfverify
    from rfverify.proof import Point
    from rfverify.report.proven import answer_digits, prove_runs

    path, _ = run_dir
    data = load_run(path)
    stats = prove_runs(data)
    assert stats["n_runs"] == len(data.solves) and stats["n_proven"] == stats["n_runs"] and not stats["no_point"]
    assert {r["method"] for r in data.solves if r["proven"]["answer"] is not None} == {"jqinv", "qp2", "clarabel"}
    for rec in [r for r in data.solves if r["problem"] == "bundled/chute"][:3]:
        problem = load(_problem_path(data, rec["problem"]))
        with np.load(data.digits[rec["problem"]]["_npz"]) as z:
            point = Point(z["ref_v"], z["point_v_lo"], z["ref_r"], z["point_r_lo"])
        with np.load(rec["_npz"]) as z:
            cert = rfverify.certify(problem, z["v"], z["u"], z["r"], point=point, digits=10)
        modes = {q: x.mode for q, x in cert.quantities.items()}
        assert rec["proven"]["answer"] == answer_digits(cert.digits, modes)
        assert rec["proven"]["answer"] < 10 <= data.digits[rec["problem"]]["certified_digits"]["v"]
    # A second report reads them from the cache.
    again = load_run(path)
    assert prove_runs(again)["n_proven"] == stats["n_proven"]
    assert [r["proven"] for r in again.solves] == [r["proven"] for r in data.solves]


def test_progress_line_shows_a_refuted_claim_as_what_it_claimed(run_dir):
    """The bench's progress line names a refuted claim by its claim and what refuted it, not by
    rfverify's own status of the answer (InsufficientProgress, ...)."""
    from rfverify.bench.execution import outcome

    path, _ = run_dir
    rec = next(r for r in _records(path, "solve") if r["refuted"])
    line = outcome(path, {"problem": rec["problem"], "kind": "solve", "method": rec["method"], "tol": rec["tol"]})
    assert line.startswith(f"{rec['claim']} (refuted: ") and "(not verified" in line, line


def test_the_hard_iterations_table_counts_iterations_not_iterates(run_dir):
    """The table 'cond(Q_p) and λ2 per iteration' printed len(iterates), the start point included:
    one more than the trajectory's own nit (an audit found 15 against 14)."""
    path, _ = run_dir
    make_report(path, diagnose_count=0, diagnose_max_contacts=4)
    section = (path / "summary.md").read_text().split("## cond(Q_p) and λ2 per iteration", 1)[1].split("\n## ", 1)[0]
    rows = [line.split("|")[1:-1] for line in section.splitlines() if line.startswith("|")][2:]
    assert rows
    for row in rows:
        cells = [c.strip() for c in row]
        problem, iterations = cells[1], int(cells[3])
        found = list(path.glob(f"runs/{problem}/trajectory-jqinv@*.json")) or \
            list(path.glob(f"runs/*/{problem}/trajectory-jqinv@*.json"))
        assert len(found) == 1, problem
        traj = json.loads(found[0].read_text())
        assert iterations == traj["nit"] == len(traj["iterates"]) - 1
