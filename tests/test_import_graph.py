"""Issue 29: the import graph of rfverify has no cycle and no package reaches into another's
private names or modules.

Function-level imports count: a cycle hidden inside a function is still two modules that
cannot be understood, tested or replaced one without the other.  The graph is read from the
sources (``ast``), with the same resolution of relative imports as tests/test_layering.py.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from test_layering import PACKAGE, ROOT, _module_name, imported_modules

ALLOWED_PRIVATE = {"rfverify._version"}
"""Private modules any package may import (the version string has one home)."""


def _modules(root: Path) -> dict:
    return {_module_name(p, root)[0]: p for p in sorted((root / "rfverify").rglob("*.py"))}


def import_graph(root: Path) -> dict:
    """module → the rfverify modules it imports (the longest module prefix of each name)."""
    mods = _modules(root)
    graph = {}
    for module, path in mods.items():
        deps = set()
        for _, name in imported_modules(path, root):
            parts = name.split(".")
            while parts and ".".join(parts) not in mods:
                parts.pop()
            target = ".".join(parts)
            if target and target != module:
                deps.add(target)
        graph[module] = deps
    return graph


def cycles(graph: dict) -> list:
    """The strongly connected components with more than one module (Tarjan, iterative)."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []
    counter = 0
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def _package_of(module: str, mods: dict) -> str:
    return module if mods[module].name == "__init__.py" else module.rsplit(".", 1)[0]


def private_cross_package_imports(root: Path) -> list:
    """``file:line`` of every ``from X import _name`` or import of a private module (a dotted
    part starting with ``_``) whose owner lies in another package than the importer."""
    mods = _modules(root)
    bad = []
    for module, path in mods.items():
        here = _package_of(module, mods)
        package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom):
                continue
            if node.level:
                base = package[:len(package) - (node.level - 1)] if node.level > 1 else package
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            if not target.startswith("rfverify"):
                continue
            for alias in node.names:
                full = f"{target}.{alias.name}"
                owner = full if full in mods else target
                if owner not in mods or owner in ALLOWED_PRIVATE:
                    continue
                private_name = alias.name.startswith("_") and not alias.name.startswith("__")
                private_module = any(p.startswith("_") and not p.startswith("__") for p in owner.split(".")[1:])
                if (private_name or private_module) and _package_of(owner, mods) != here:
                    bad.append(f"{path.relative_to(root).as_posix()}:{node.lineno} {target} import {alias.name}")
    return bad


def test_the_import_graph_has_no_cycle():
    assert cycles(import_graph(ROOT)) == [], (
        "modules that import each other (at module or function level): move what both need "
        "into a module both import")


def test_no_package_imports_another_packages_private_names():
    assert private_cross_package_imports(ROOT) == [], "make the name public in its package, or move it"


@pytest.mark.parametrize("graph, expected", [
    ({"a": {"b"}, "b": {"a"}}, [["a", "b"]]),
    ({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}, [["a", "b", "c"]]),
    ({"a": {"b"}, "b": set(), "c": {"b"}}, []),
])
def test_the_cycle_finder_finds_cycles(graph, expected):
    assert sorted(cycles(graph)) == expected


def test_the_checks_see_function_level_and_private_imports(tmp_path):
    pkg = tmp_path / "rfverify"
    (pkg / "a").mkdir(parents=True)
    (pkg / "b").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a" / "__init__.py").write_text("")
    (pkg / "b" / "__init__.py").write_text("")
    (pkg / "a" / "x.py").write_text("def f():\n    from ..b import y\n")
    (pkg / "b" / "y.py").write_text("from ..a.x import f\n_hidden = 1\n")
    (pkg / "b" / "z.py").write_text("from . import y\n")
    (pkg / "a" / "w.py").write_text("from ..b.y import _hidden\n")
    assert cycles(import_graph(tmp_path)) == [["rfverify.a.x", "rfverify.b.y"]]
    assert private_cross_package_imports(tmp_path) == ["rfverify/a/w.py:1 rfverify.b.y import _hidden"]


def test_the_package_scanned_is_the_installed_one():
    assert PACKAGE == ROOT / "rfverify" and (PACKAGE / "__init__.py").exists()
