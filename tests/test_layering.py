"""The packages depend on each other in one direction only, and no two modules import each other.

``sysid`` imports nothing of this project, ``twins`` only ``sysid``, the benchmark library (``benchmarks``
outside ``benchmarks/cli``) only ``sysid`` and ``twins``; the CLI package ``benchmarks.cli`` sits on top and
nothing below imports it. Every import statement counts, also one inside a function: a function-local import
is still a dependency, it only runs later. The same holds for cycles: a cycle closed by a function-local
import (the usual way to dodge an import error) is still two modules that need each other, so it is reported
too. Only imports under ``if TYPE_CHECKING:`` are left out of the cycle search, they never run.

The checker reads the source with :mod:`ast`, so a docstring that merely names ``benchmarks.execution`` is
not an import. The last two tests run it on a small made-up tree to show that it does report a wrong
import and a cycle.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("sysid", "twins", "benchmarks")
CLI = "benchmarks.cli"


@dataclass(frozen=True)
class Edge:
    source: str  # importing module, dotted
    target: str  # imported module (the deepest one that exists in the tree), dotted
    path: str
    line: int
    runtime: bool  # False for imports under ``if TYPE_CHECKING:``

    def __str__(self) -> str:
        return f"{self.path}:{self.line}: {self.source} imports {self.target}"


def _module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules(root: Path, packages=PACKAGES) -> dict[str, Path]:
    out = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            out[_module_name(root, path)] = path
    return out


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.AST):
    """Yield (node, runtime) for every import statement, function bodies included."""
    def walk(node: ast.AST, runtime: bool):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                yield child, runtime
            elif isinstance(child, ast.If) and _is_type_checking(child.test):
                for stmt in child.body:
                    yield from walk(ast.Module(body=[stmt], type_ignores=[]), False)
                for stmt in child.orelse:
                    yield from walk(ast.Module(body=[stmt], type_ignores=[]), runtime)
            else:
                yield from walk(child, runtime)
    yield from walk(tree, True)


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The deepest existing module that ``name`` (possibly ``module.attribute``) names."""
    parts = name.split(".")
    while parts:
        cand = ".".join(parts)
        if cand in modules:
            return cand
        parts.pop()
    return None


def import_edges(root: Path, packages=PACKAGES) -> list[Edge]:
    """Every import of one of ``packages`` by a module of ``packages`` under ``root``."""
    modules = _modules(root, packages)
    edges = []
    for src, path in modules.items():
        is_pkg = path.name == "__init__.py"
        rel = str(path.relative_to(root))
        for node, runtime in _imports(ast.parse(path.read_text(encoding="utf-8"), filename=rel)):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                if node.level:
                    base = src.split(".")
                    base = base[: len(base) - node.level + (1 if is_pkg else 0)]
                    mod = ".".join(base + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                # ``from pkg import sub`` imports the submodule pkg.sub when there is one
                names = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in modules else mod for a in node.names]
            for name in names:
                target = _resolve(name, modules)
                if target is not None and target != src:
                    edges.append(Edge(src, target, rel, node.lineno, runtime))
    return edges


def _layer(module: str) -> int:
    top = module.split(".")[0]
    if top == "sysid":
        return 0
    if top == "twins":
        return 1
    if module == CLI or module.startswith(CLI + "."):
        return 3
    return 2  # the benchmark library


def layering_violations(edges: list[Edge]) -> list[str]:
    """Imports that point upward: sysid → twins/benchmarks, twins → benchmarks, library → CLI."""
    return sorted(str(e) for e in edges if _layer(e.target) > _layer(e.source))


def import_cycles(edges: list[Edge]) -> list[list[str]]:
    """Strongly connected groups of more than one module in the graph of run-time imports (Tarjan)."""
    graph: dict[str, set[str]] = {}
    for e in edges:
        if e.runtime:
            graph.setdefault(e.source, set()).add(e.target)
            graph.setdefault(e.target, set())
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                out.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(out)


def _describe(cycles: list[list[str]], edges: list[Edge]) -> list[str]:
    lines = []
    for group in cycles:
        members = set(group)
        lines.append(" <-> ".join(group) + ": " + "; ".join(dict.fromkeys(
            str(e) for e in edges if e.runtime and e.source in members and e.target in members)))
    return lines


# ---------------------------------------------------------------------------------------------- the project
def test_no_upward_imports():
    edges = import_edges(ROOT)
    assert len(edges) > 100  # the checker did find the project's own imports
    assert layering_violations(edges) == []


def test_no_import_cycles():
    edges = import_edges(ROOT)
    cycles = import_cycles(edges)
    assert _describe(cycles, edges) == []


# ------------------------------------------------------------------------------- the checker can say no
def _write(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")


def _toy_tree(root: Path) -> None:
    _write(
        root,
        {
            "sysid/__init__.py": '"""Mentions benchmarks.cli and twins.base in prose only."""\n',
            "sysid/signals.py": "import numpy as np\n",
            "sysid/record.py": ("def load():\n    from twins.base import Twin  # upward, function-local\n"
                                "    return Twin\n"),
            "twins/__init__.py": "",
            "twins/base.py": ("from sysid.signals import np\n\ndef fit():\n    from twins.calibration import go\n"
                              "    return go\n"),
            "twins/calibration.py": "from twins.base import fit\n\ndef go():\n    return fit\n",
            "twins/typed.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from twins.quiet import Q\n",
            "twins/quiet.py": "from twins import typed\n",
            "benchmarks/__init__.py": "",
            "benchmarks/scoring.py": "from . import cli\nfrom twins import base\n",
            "benchmarks/cli/__init__.py": "from benchmarks.scoring import *\nfrom sysid import record\n",
        },
    )


def test_checker_reports_a_wrong_import(tmp_path):
    _toy_tree(tmp_path)
    bad = layering_violations(import_edges(tmp_path))
    assert bad == ["benchmarks/scoring.py:1: benchmarks.scoring imports benchmarks.cli",
                   "sysid/record.py:2: sysid.record imports twins.base"]


def test_checker_reports_a_cycle(tmp_path):
    _toy_tree(tmp_path)
    edges = import_edges(tmp_path)
    cycles = import_cycles(edges)
    # base <-> calibration (one side function-local) and scoring <-> cli; the TYPE_CHECKING pair is no cycle
    assert cycles == [["benchmarks.cli", "benchmarks.scoring"], ["twins.base", "twins.calibration"]]
    assert "twins/base.py:4: twins.base imports twins.calibration" in _describe(cycles, edges)[1]
