"""Issue 14 item 3, layering: the CLI is the top layer (no module outside ``rfverify/cli/``
imports it), every package is installed, and the method names are declared once."""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "rfverify"
CLI = "rfverify.cli"

ENTRY_POINTS = {"rfverify/__main__.py"}
"""``python -m rfverify`` runs the CLI, as the console script does: an entry point, not a layer."""


def _module_name(path: Path, root: Path) -> tuple[str, bool]:
    """Dotted name of a source file and whether it is a package's ``__init__``."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    is_init = parts[-1] == "__init__"
    return ".".join(parts[:-1] if is_init else parts), is_init


def imported_modules(path: Path, root: Path) -> list[tuple[int, str]]:
    """(line, absolute module name) of every import in ``path`` — relative imports resolved,
    ``from X import name`` counted as X and X.name (name may be a submodule), and
    ``importlib.import_module("...")`` / ``__import__("...")`` with a literal name."""
    module, is_init = _module_name(path, root)
    package = module.split(".") if is_init else module.split(".")[:-1]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - (node.level - 1)] if node.level > 1 else package
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if node.module:
                found.append((node.lineno, target))
            found += [(node.lineno, f"{target}.{a.name}") for a in node.names if a.name != "*"]
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", None)
            if name in ("import_module", "__import__") and isinstance(node.args[0].value, str):
                found.append((node.lineno, node.args[0].value))
    return found


def cli_importers(root: Path) -> list[str]:
    """``file:line module`` for every import of rfverify.cli outside rfverify/cli/."""
    bad = []
    for path in sorted((root / "rfverify").rglob("*.py")):
        rel = path.relative_to(root).as_posix()
        if rel.startswith("rfverify/cli/") or rel in ENTRY_POINTS:
            continue
        for line, name in imported_modules(path, root):
            if name == CLI or name.startswith(CLI + "."):
                bad.append(f"{rel}:{line} {name}")
    return bad


def test_no_module_outside_the_cli_package_imports_it():
    assert cli_importers(ROOT) == [], ("the CLI is the top layer: move what these modules need "
                                       "out of rfverify/cli/ into the library")


@pytest.mark.parametrize("source, where", [
    ("from rfverify.cli import main\n", "rfverify/bench/x.py"),
    ("import rfverify.cli.app\n", "rfverify/bench/x.py"),
    ("from ..cli.argtypes import tolerance\n", "rfverify/bench/x.py"),
    ("from ..cli import common\n", "rfverify/report/x.py"),
    ("from .cli import main\n", "rfverify/summary_x.py"),
    ("from . import cli\n", "rfverify/summary_x.py"),
    ("def f():\n    from .. import cli\n", "rfverify/io/x.py"),
    ("import importlib\nimportlib.import_module('rfverify.cli')\n", "rfverify/x.py"),
])
def test_the_layering_check_finds_every_form_of_import(tmp_path, source, where):
    for pkg in ("rfverify", "rfverify/cli", "rfverify/bench", "rfverify/report", "rfverify/io"):
        (tmp_path / pkg).mkdir(parents=True, exist_ok=True)
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "rfverify/cli/app.py").write_text("from ..bench import x\n")  # allowed direction
    assert cli_importers(tmp_path) == []
    (tmp_path / where).write_text(source)
    assert {b.split(":")[0] for b in cli_importers(tmp_path)} == {where}


def test_relative_imports_resolve_inside_the_cli_package():
    names = {n for _, n in imported_modules(PACKAGE / "cli" / "app.py", ROOT)}
    assert {"rfverify.errors", "rfverify.cli.common", "rfverify.cli.bench"} <= names


def test_every_package_is_installed():
    """pyproject lists packages by hand: a new package (rfverify.cli) must be in the list, or a
    non-editable install would have no CLI."""
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    present = {p.parent.relative_to(ROOT).as_posix().replace("/", ".") for p in ROOT.glob("rfverify/**/__init__.py")}
    assert present <= listed


def test_method_names_are_declared_once():
    """METHODS in rfverify/solver/result.py is the one list of method names; the rest derive from it."""
    from rfverify.bench.runner import DEFAULT_METHODS
    from rfverify.report.data import RunData
    from rfverify.solver.result import ALGORITHM1_METHODS, AUTO_SEQUENCE, METHODS, PEER_METHODS, PORTFOLIO_METHODS

    assert METHODS == ALGORITHM1_METHODS + PORTFOLIO_METHODS + PEER_METHODS
    assert set(AUTO_SEQUENCE) <= set(ALGORITHM1_METHODS)
    assert set(DEFAULT_METHODS) < set(METHODS)
    data = RunData(Path("."), {}, {}, solves=[{"method": m} for m in reversed(METHODS)])
    assert data.methods == list(METHODS)
    from rfverify.report.figures import _LINE, _STYLE  # per-method styles: one for every method

    assert set(METHODS) <= set(_STYLE) and set(METHODS) <= set(_LINE)
    # No other source spells out a list of three or more method names.
    listing = re.compile(r"""[\[(]\s*(["'](%s)["']\s*,\s*){2,}""" % "|".join(METHODS))
    where = [p.relative_to(ROOT).as_posix() for d in ("rfverify", "benchmarks")
             for p in sorted((ROOT / d).rglob("*.py")) if listing.search(p.read_text(encoding="utf-8"))]
    assert where == ["rfverify/solver/result.py"]


ARCHITECTURE = ROOT / "docs" / "ARCHITECTURE.md"

LAYER_EXCEPTIONS = {("rfverify.io.certificate", "rfverify.proof"), ("rfverify.extended.wide", "rfverify.proof")}
"""Upward imports docs/ARCHITECTURE.md names: function-local imports of the ``proof.Point`` type."""


def architecture_layers(text: str) -> list[tuple[str, list[str]]]:
    """(layer, module names) of the table under "## Layers": `x.py` is rfverify.x, `p/` the
    package rfverify.p, and names in parentheses after a package its modules."""
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    layers = []
    for row in re.findall(r"^\| ([a-z ]+) \| (.+?) \| .+ \|$", section, re.M):
        name, cell = row
        if name.strip() == "layer":
            continue
        mods, last, inside = [], None, None
        for token in re.findall(r"`[^`]+`|\(|\)", cell):
            if token == "(":
                inside = last  # names in parentheses right after a package are its modules
                continue
            if token == ")":
                inside = None
                continue
            token = token.strip("`")
            if token.endswith("/"):
                last = f"rfverify.{token[:-1]}"
                mods.append(last)
            elif token.endswith(".py"):
                stem = token[:-3]
                mods.append(f"{inside}.{stem}" if inside else f"rfverify.{stem}")
                last = None
            else:
                last = None
        layers.append((name.strip(), mods))
    return layers


def _layer_of(module: str, layers) -> int | None:
    best, depth = None, -1
    for i, (_, mods) in enumerate(layers):
        for m in mods:
            if (module == m or module.startswith(m + ".")) and m.count(".") > depth:
                best, depth = i, m.count(".")
    return best


def test_architecture_names_modules_that_exist_and_every_module_has_a_layer():
    """docs/ARCHITECTURE.md describes the code as it is: a module it names that disappears, or a
    module it does not place, fails here."""
    layers = architecture_layers(ARCHITECTURE.read_text(encoding="utf-8"))
    assert [n for n, _ in layers][:2] == ["data", "algebra"] and layers[-1][0] == "front end"
    for _, mods in layers:
        for m in mods:
            path = ROOT / Path(*m.split("."))
            assert path.with_suffix(".py").is_file() or (path / "__init__.py").is_file(), \
                f"docs/ARCHITECTURE.md names {m}, which does not exist"
    for path in sorted(PACKAGE.rglob("*.py")):
        module, _ = _module_name(path, ROOT)
        if module != "rfverify":
            assert _layer_of(module, layers) is not None, f"{module} is in no layer of docs/ARCHITECTURE.md"


def test_imports_go_only_to_the_same_or_a_higher_layer():
    layers = architecture_layers(ARCHITECTURE.read_text(encoding="utf-8"))
    bad = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module, _ = _module_name(path, ROOT)
        own = _layer_of(module, layers)
        if module == "rfverify" or own is None:
            continue
        for line, name in imported_modules(path, ROOT):
            other = _layer_of(name, layers) if name.startswith("rfverify.") else None
            if other is not None and other > own and not any(
                    module.startswith(a) and name.startswith(b) for a, b in LAYER_EXCEPTIONS):
                bad.append(f"{path.relative_to(ROOT)}:{line} ({layers[own][0]}) imports {name} ({layers[other][0]})")
    assert not bad, "imports against the layers of docs/ARCHITECTURE.md:\n" + "\n".join(sorted(set(bad)))


# ---------------------------------------------------------------- the house rules (issue 50)
ROOT_MODULES_MAX = 7
"""Modules at the package root (``__init__`` and ``__main__`` included): the rest live in the
package that owns them (docs/ARCHITECTURE.md)."""
MODULE_LINES_MAX = 600
FUNCTION_CODE_LINES_MAX = 100
"""Lines of code of one function: its body after the docstring, blank and comment-only lines
not counted."""
NO_PROBING = ("algorithm", "extended")
"""Packages whose interfaces are typing.Protocols with default hooks: no ``hasattr`` there."""


def _sources(root: Path):
    return sorted((root / "rfverify").rglob("*.py"))


def root_modules(root: Path) -> list[str]:
    return sorted(p.name for p in (root / "rfverify").glob("*.py"))


def long_modules(root: Path) -> list[str]:
    return [f"{p.relative_to(root)}: {n} lines" for p in _sources(root)
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MODULE_LINES_MAX]


def function_code_lines(node: ast.AST, lines: list[str]) -> int:
    body = node.body
    first = body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        if len(body) == 1:
            return 0
        first = body[1]
    return sum(1 for line in lines[first.lineno - 1:node.end_lineno]
               if line.strip() and not line.strip().startswith("#"))


def long_functions(root: Path) -> list[str]:
    bad = []
    for p in _sources(root):
        text = p.read_text(encoding="utf-8")
        lines = text.splitlines()
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = function_code_lines(node, lines)
                if n > FUNCTION_CODE_LINES_MAX:
                    bad.append(f"{p.relative_to(root)}:{node.lineno} {node.name}: {n} lines of code")
    return bad


def hasattr_probes(root: Path) -> list[str]:
    bad = []
    for package in NO_PROBING:
        for p in sorted((root / "rfverify" / package).rglob("*.py")):
            for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "hasattr":
                    bad.append(f"{p.relative_to(root)}:{node.lineno}")
    return bad


def private_imports(root: Path) -> list[str]:
    """``from M import _name`` where M is not itself a private module: a module's private names
    are its own (a package's private modules, ``jordan._formulas``, are that package's insides)."""
    bad = []
    for p in _sources(root):
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom) or (node.module or "").split(".")[-1].startswith("_"):
                continue
            for a in node.names:
                if a.name.startswith("_") and not a.name.endswith("__"):
                    bad.append(f"{p.relative_to(root)}:{node.lineno} imports {a.name} from {node.module}")
    return bad


def test_the_package_root_holds_at_most_seven_modules():
    assert len(root_modules(ROOT)) <= ROOT_MODULES_MAX, root_modules(ROOT)


def test_no_module_is_longer_than_600_lines():
    assert long_modules(ROOT) == []


def test_no_function_has_more_than_100_lines_of_code():
    assert long_functions(ROOT) == []


def test_no_hasattr_probing_in_the_algorithm_and_the_extended_phase():
    assert hasattr_probes(ROOT) == [], "declare the hook in the Protocol with a default instead"


def test_no_private_name_is_imported_from_another_module():
    assert private_imports(ROOT) == []


def test_no_top_level_module_is_installed_beside_the_packages():
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "py-modules" not in tool["tool"]["setuptools"]
    module, _ = tool["project"]["scripts"]["rfverify"].split(":")
    assert module.startswith("rfverify."), "the console script lives inside the package"


@pytest.mark.parametrize("rule, source, where", [
    (long_modules, "x = 1\n" * (MODULE_LINES_MAX + 1), "rfverify/verify/big.py"),
    (long_functions, "def f():\n    '''doc'''\n" + "    x = 1\n" * (FUNCTION_CODE_LINES_MAX + 1), "rfverify/verify/f.py"),
    (hasattr_probes, "def f(b):\n    return hasattr(b, 'observe')\n", "rfverify/extended/x.py"),
    (private_imports, "from .digits import _start_from\n", "rfverify/verify/certification.py"),
])
def test_each_house_rule_finds_what_breaks_it(tmp_path, rule, source, where):
    for pkg in ("rfverify", "rfverify/verify", "rfverify/extended", "rfverify/algorithm"):
        (tmp_path / pkg).mkdir(parents=True, exist_ok=True)
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "rfverify/verify/ok.py").write_text(
        "from ._x import _inside\n\n\ndef g():\n    '''doc'''\n" + "    # why\n\n" * 200 + "    return 1\n")
    assert rule(tmp_path) == []
    (tmp_path / where).write_text(source)
    assert len(rule(tmp_path)) == 1


def test_a_package_root_of_eight_modules_is_too_many(tmp_path):
    (tmp_path / "rfverify").mkdir()
    for i in range(ROOT_MODULES_MAX + 1):
        (tmp_path / "rfverify" / f"m{i}.py").write_text("")
    assert len(root_modules(tmp_path)) > ROOT_MODULES_MAX


def _anchor(heading: str) -> str:
    """The anchor a Markdown renderer (GitHub) gives a heading."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_architecture_is_a_map_of_short_lines():
    """Readable in five minutes: no paragraph-long table rows (issue 50)."""
    long = [i for i, line in enumerate(ARCHITECTURE.read_text(encoding="utf-8").splitlines(), 1) if len(line) > 400]
    assert long == [], f"docs/ARCHITECTURE.md lines over 400 characters: {long}"


def test_decisions_open_with_an_index_by_topic_whose_links_resolve():
    """docs/DECISIONS.md: an index by topic first (each topic's decision in force, then its
    sections), then the history; every link of the index names a section that exists."""
    text = (ROOT / "docs" / "DECISIONS.md").read_text(encoding="utf-8")
    first = re.search(r"^## (.+)$", text, re.M).group(1)
    assert first == "Index by topic"
    index = text.split("## Index by topic", 1)[1].split("\n## ", 1)[0]
    anchors = {_anchor(h) for h in re.findall(r"^#{2,3} (.+)$", text, re.M)}
    links = re.findall(r"\]\(#([^)]+)\)", index)
    assert len(links) >= 15 and set(links) <= anchors, sorted(set(links) - anchors)
    assert index.count("\n- **") >= 10  # topics, each with its current decision
