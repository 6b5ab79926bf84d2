"""The documents say what the program does today (issue 28 item 4): the README's two commands are
the ones CI runs and the README stays short; the TUTORIAL's commands, run in a temporary
directory, print the lines it quotes (timings and the last digits of rounding-level residuals
aside); the DESIGN sections that messages and ``--help`` cite exist, in the copy installed with
the package."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
TUTORIAL = ROOT / "docs" / "TUTORIAL.md"
in_repo = pytest.mark.skipif(not (ROOT / ".ci" / "run").is_file() or not README.is_file(),
                             reason="needs the repository checkout (README, .ci/run)")


# --- README -------------------------------------------------------------------------------

def _bash_blocks(text: str) -> list[str]:
    return [b.strip() for b in re.findall(r"```bash\n(.*?)```", text, re.S)]


@in_repo
def test_readme_is_short_and_its_two_commands_are_what_ci_runs():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 150, "README.md over 150 lines: move the detail to docs/"
    install, tests = _bash_blocks(text.split("## Start here", 1)[1])[:2]
    # .ci/run's sections "README step 1" and "README step 2": their unindented commands.
    sections, current = {}, None
    for line in (ROOT / ".ci" / "run").read_text().splitlines():
        m = re.match(r'echo "== .*\(README (step \d)\) =="', line)
        if line.startswith('echo "=='):
            current = m.group(1) if m else None
        elif current and line and not line[0].isspace() and not line.startswith(("#", "echo ")):
            sections.setdefault(current, []).append(line.strip())
    assert [c.strip() for c in install.split("&&")] == sections["step 1"]
    assert [tests] == sections["step 2"]


@in_repo
def test_readme_links_resolve():
    text = README.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if not target.startswith("http"):
            assert (ROOT / target).exists(), f"README links to {target}, which does not exist"


# --- DESIGN references ----------------------------------------------------------------------

def _design_sections(path: Path) -> set[str]:
    return {m.group(1) for m in re.finditer(r"^#{2,3} (\d+(?:\.\d+)?[a-z]?)[. ]", path.read_text(encoding="utf-8"),
                                            re.M)}


def test_design_references_resolve_in_the_installed_docs():
    """Every "DESIGN §k" that a message, docstring or --help cites names a section of the DESIGN.md
    installed with the package (rfverify/docs, package data), and --help says where that is."""
    import rfverify
    from rfverify.cli.app import COMMANDS, build_parser
    from rfverify.cli.common import DOCS_DIR

    pkg = Path(rfverify.__file__).parent
    assert DOCS_DIR == pkg / "docs" or DOCS_DIR.resolve() == (pkg / "docs").resolve()
    sections = _design_sections(DOCS_DIR / "DESIGN.md")
    assert {"4.5", "6", "6.1b", "6.3"} <= sections
    texts = [p.read_text(encoding="utf-8") for p in sorted(pkg.rglob("*.py"))]
    parser = build_parser()
    helps = [parser.format_help()]
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    helps += [sub.choices[c.__name__.rsplit(".", 1)[-1]].format_help() for c in COMMANDS]
    cited = set()
    for text in texts + helps:
        cited |= set(re.findall(r"DESIGN(?:\.md)? ?§ ?(\d+(?:\.\d+)?[a-z]?)", text))
    assert cited and cited <= sections, f"cited but not in DESIGN.md: {sorted(cited - sections)}"
    for text in helps:
        for name in re.findall(r"\b([A-Z]+\.md)\b", text):
            assert (DOCS_DIR / name).is_file(), name
        assert "docs/DESIGN.md in the source repository" not in text
    assert str(DOCS_DIR) in " ".join(helps[0].split()).replace("- ", "-") or str(DOCS_DIR) in helps[0].replace("\n", "")


@in_repo
def test_docs_are_package_data():
    """A wheel carries the docs: rfverify/docs is the repository's docs/ and pyproject ships it."""
    import tomllib

    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "docs/*.md" in conf["tool"]["setuptools"]["package-data"]["rfverify"]
    linked = ROOT / "rfverify" / "docs"
    assert linked.resolve() == (ROOT / "docs").resolve()
    assert {p.name for p in linked.glob("*.md")} >= {"DESIGN.md", "TUTORIAL.md", "REFERENCE.md", "RESULTS.md"}


# --- TUTORIAL -------------------------------------------------------------------------------

def console_steps(block: str) -> list[dict]:
    """The ``$ command`` lines of one console block (a here-document runs to its terminator),
    each with the output lines quoted under it."""
    lines, steps, i = block.splitlines(), [], 0
    while i < len(lines):
        line = lines[i]
        if not line.startswith("$ "):
            i += 1
            continue
        cmd = [line[2:]]
        m = re.search(r"<<'?(\w+)'?", line)
        if m:
            while lines[i] != m.group(1):
                i += 1
                cmd.append(lines[i])
        i += 1
        out = []
        while i < len(lines) and not lines[i].startswith("$ "):
            out.append(lines[i])
            i += 1
        steps.append({"cmd": "\n".join(cmd), "expect": out})
    return steps


def tutorial_steps(text: str) -> list[dict]:
    """The steps of the tutorial's ```console blocks; then each ```python block with the plain
    block after "prints"."""
    steps = []
    for block in re.findall(r"```console\n(.*?)```", text, re.S):
        steps += console_steps(block)
    for code, printed in re.findall(r"```python\n(.*?)```\s*\n\s*prints\s*\n\s*```\n(.*?)```", text, re.S):
        steps.append({"cmd": "python - <<'PYEOF'\n" + code + "PYEOF", "expect": printed.splitlines()})
    return steps


_NUM = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:e[-+]?\d+)?")


def _normalise(line: str) -> str:
    """Timings removed: whatever follows "time " up to ";" (a cold start adds a compile entry),
    and every number of seconds ("N s")."""
    line = re.sub(r"\btime [^;]*", "time <T>", line)
    return re.sub(r"\b[\d.]+ s\b", "<T> s", line)


def _numbers_agree(a: str, b: str) -> bool:
    x, y = float(a), float(b)
    if "." not in a and "e" not in a.lower():  # counts, indices, iterations: exact
        return x == y
    if abs(x) < 1e-12 and abs(y) < 1e-12:  # rounding-level residuals (they vary with the machine's BLAS)
        return True
    return abs(x - y) <= 0.05 * max(abs(x), abs(y))


def line_matches(expected: str, got: str) -> bool:
    e, g = _normalise(expected), _normalise(got)
    if _NUM.sub("#", e) != _NUM.sub("#", g):
        return False
    return all(_numbers_agree(a, b) for a, b in zip(_NUM.findall(e), _NUM.findall(g)))


def run_steps(workdir: Path, steps: list[dict], *, env: dict | None = None, timeout: float = 240) -> list[str]:
    """Run ``steps`` (see :func:`console_steps`) in one shell in ``workdir``, with this Python's
    scripts first on PATH and ``env`` added; the mismatches with what they quote, one per line
    ("…" lines and blank ones are not checked; ``echo $?`` checks the previous exit code)."""
    script = ["set +e"]
    for k, s in enumerate(steps):
        if s["cmd"] == "echo $?":
            continue
        script += [f"echo '@@{k}'", "{", s["cmd"], "} 2>&1", f"echo \"@@rc $?\""]
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "PYTHONUNBUFFERED": "1", "COLUMNS": "200", **(env or {})}
    out = subprocess.run(["bash", "-c", "\n".join(script)], cwd=workdir, env=env, capture_output=True,
                         text=True, timeout=timeout).stdout
    got, rc, current = {}, {}, None
    for line in out.splitlines():
        if line.startswith("@@rc "):
            rc[current] = int(line[5:])
        elif re.fullmatch(r"@@\d+", line):
            current = int(line[2:])
            got[current] = []
        elif current is not None:
            got[current].append(line)
    problems, last = [], None
    for k, s in enumerate(steps):
        if s["cmd"] == "echo $?":
            want = int(s["expect"][0])
            if rc.get(last) != want:
                problems.append(f"`{steps[last]['cmd']}`: exit code {rc.get(last)}, the tutorial says {want}")
            continue
        last = k
        for line in s["expect"]:
            if "…" in line or not line.strip():
                continue
            if not any(line_matches(line, g) for g in got.get(k, [])):
                problems.append(f"`{s['cmd'].splitlines()[0]}`: quoted line not printed: {line!r}\n"
                                f"    printed: {got.get(k)}")
    return problems


def run_tutorial(workdir: Path, text: str) -> list[str]:
    """Run the tutorial's commands in one shell in ``workdir``; the mismatches, one per line."""
    return run_steps(workdir, tutorial_steps(text))


def test_tutorial_line_matching_is_tolerant_of_timings_only():
    assert line_matches("iterations 20, time 0.186 s; the paper's measures: pinfeas 6.28e-17",
                        "iterations 20, time 1.5 s (compiling kernels 1.2); the paper's measures: pinfeas 1.1e-17")
    assert line_matches("  v: 10.6 digits (|error| ≤ 4.59e-10)", "  v: 10.6 digits (|error| ≤ 4.61e-10)")
    assert not line_matches("  v: 10.6 digits (|error| ≤ 4.59e-10)", "  v: 9.6 digits (|error| ≤ 4.59e-10)")
    assert not line_matches("iterations 20, time 0.1 s", "iterations 21, time 0.1 s")
    assert line_matches("Solved in 16 iterations, 2.04 s", "Solved in 16 iterations, 0.2 s")
    assert not line_matches("Solved in 16 iterations, 2.04 s", "Solved in 17 iterations, 2.04 s")
    assert not line_matches("status Solved: all 2 components solved", "status Solved: all 3 components solved")
    steps = tutorial_steps("```console\n$ a x\nout 1\n$ echo $?\n0\n$ python - <<'EOF'\nprint(1)\nEOF\n1\n```\n")
    assert [s["cmd"] for s in steps] == ["a x", "echo $?", "python - <<'EOF'\nprint(1)\nEOF"]
    assert steps[0]["expect"] == ["out 1"] and steps[2]["expect"] == ["1"]


@in_repo
def test_tutorial_commands_print_what_it_quotes(tmp_path):
    problems = run_tutorial(tmp_path, TUTORIAL.read_text(encoding="utf-8"))
    assert not problems, "docs/TUTORIAL.md disagrees with the program:\n" + "\n".join(problems)


def test_solve_help_says_how_3d_and_local_files_are_solved(capsys):
    from rfverify.cli import main

    with pytest.raises(SystemExit):
        main(["solve", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for phrase in ("/fclib_global, /fclib_local", "convex relaxation", "mu_r = 0", "DESIGN §7.2", "own W",
                   "Exit codes: 0 "):
        assert phrase in text, phrase


@in_repo
def test_reference_lists_the_methods_and_bench_defaults_the_cli_accepts():
    """docs/REFERENCE.md's command summary names every ``--method`` choice and ``bench``'s
    default methods as the code declares them (it had lost ``schur`` and ``siconos``)."""
    from rfverify.bench.runner import DEFAULT_METHODS
    from rfverify.solver.result import METHODS

    text = (ROOT / "docs" / "REFERENCE.md").read_text(encoding="utf-8")
    solve_methods = re.search(r"rfverify solve +PROBLEM \[--method ([a-z0-9_|]+)\]", text).group(1).split("|")
    assert sorted(solve_methods) == sorted(METHODS)
    bench_methods = re.search(r"rfverify bench .*?\[--methods ([a-z0-9_,]+)\]", text).group(1).split(",")
    assert bench_methods == list(DEFAULT_METHODS)
