"""The packages depend on each other in one direction only, and no two modules need each other.

``sysid`` imports nothing of this project, ``twins`` only ``sysid``, the benchmark library (``benchmarks``
outside ``benchmarks/cli``) only ``sysid`` and ``twins``; the CLI package ``benchmarks.cli`` sits on top and
nothing below imports it. Inside ``sysid`` the same holds between its families (:data:`SYSID_FLOORS`): a module
imports only its own family and the floors below it, never a sibling on its own floor.

Every import statement counts, also one inside a function: a function-local import is still a dependency, it
only runs later. The cycle search takes imports under ``if TYPE_CHECKING:`` too: two modules that name each
other's types are still one tangle. The one exception is a package's ``__init__`` re-exporting the names of
its own modules under ``if TYPE_CHECKING:`` (:mod:`sysid._exports`): that lists, it does not depend.

The checker reads the source with :mod:`ast`, so a docstring that merely names ``benchmarks.execution`` is
not an import. The last tests run it on a small made-up tree to show that it does report a wrong import, a
cycle and a family that imports a higher one.
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
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


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


# The floors of sysid, lowest first: a module may import its own family and any family on a lower floor. A family
# is a sub-package or a top-level module; the package ``sysid`` itself (its __init__) stands on top of them all.
SYSID_FLOORS: tuple[tuple[str, ...], ...] = (
    ("sysid.errors", "sysid._blas", "sysid.progress", "sysid._exports"),
    ("sysid.config", "sysid.registry"),
    ("sysid.data",),
    ("sysid.signals", "sysid.evaluation"),
    ("sysid.report",),
    ("sysid.base",),
    ("sysid.polynomial",),
    ("sysid.linear",),
    ("sysid.nonlinear", "sysid.neural"),
    ("sysid.identify", "sysid.stepper", "sysid.search"),
)


def _family(module: str, floors=SYSID_FLOORS) -> tuple[int, str] | None:
    """(floor, family) of a module of sysid; None for the package ``sysid`` itself (its re-exports)."""
    for k, families in enumerate(floors):
        for fam in families:
            if module == fam or module.startswith(fam + "."):
                return k, fam
    if module == "sysid":
        return None
    raise AssertionError(f"{module} belongs to no family of SYSID_FLOORS: add it to one")


def family_violations(edges: list[Edge], floors=SYSID_FLOORS) -> list[str]:
    """Imports inside sysid that reach a higher floor or a sibling family on the same floor."""
    bad = []
    for e in edges:
        if not (e.source.startswith("sysid.") and e.target.startswith("sysid.")):
            continue
        src, dst = _family(e.source, floors), _family(e.target, floors)
        if src is None or dst is None or src[1] == dst[1]:
            continue
        if dst[0] >= src[0]:
            bad.append(f"{e} (floor {src[0]} {src[1]} -> floor {dst[0]} {dst[1]})")
    return sorted(bad)


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
    """Strongly connected groups of more than one module in the graph of imports, type-only ones included (Tarjan).

    Left out: a package's TYPE_CHECKING imports of its own modules (the list of names it re-exports lazily).
    """
    graph: dict[str, set[str]] = {}
    for e in edges:
        if e.runtime or not e.target.startswith(e.source + "."):
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
        lines.append(
            " <-> ".join(group)
            + ": "
            + "; ".join(dict.fromkeys(str(e) for e in edges if e.source in members and e.target in members))
        )
    return lines


# ---------------------------------------------------------------------------------------------- the project
def test_no_upward_imports():
    edges = import_edges(ROOT)
    assert len(edges) > 100  # the checker did find the project's own imports
    assert layering_violations(edges) == []


def test_sysid_families_import_downward_only():
    edges = import_edges(ROOT)
    assert sum(e.source.startswith("sysid.") and e.target.startswith("sysid.") for e in edges) > 100
    assert family_violations(edges) == []


def test_every_sysid_module_has_a_family_and_sysid_stays_small():
    """Every module of sysid is placed on a floor, and sysid/ keeps at most 12 top-level modules."""
    modules = _modules(ROOT, ("sysid",))
    for m in modules:
        _family(m)  # raises for a module no floor names
    top = [p.name for p in (ROOT / "sysid").glob("*.py") if p.name != "__init__.py"]
    assert len(top) <= 12, sorted(top)


def test_every_family_says_what_it_holds_and_may_import():
    for init in sorted((ROOT / "sysid").glob("*/__init__.py")):
        doc = ast.get_docstring(ast.parse(init.read_text(encoding="utf-8"))) or ""
        assert len(doc.split()) >= 20, f"{init}: the docstring should say what lives there"
        assert "May import:" in doc, f"{init}: the docstring should say what the family may import"


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
            "sysid/signals/__init__.py": "",
            "sysid/signals/gen.py": "import numpy as np\nfrom sysid.report.figs import draw  # a higher floor\n",
            "sysid/report/__init__.py": "",
            "sysid/report/figs.py": "def draw():\n    return 1\n",
            "sysid/data/__init__.py": "",
            "sysid/data/record.py": (
                "def load():\n    from twins.base import Twin  # upward, function-local\n    return Twin\n"
            ),
            "twins/__init__.py": "",
            "twins/base.py": (
                "from sysid.signals.gen import np\n\ndef fit():\n    from twins.calibration import go\n    return go\n"
            ),
            "twins/calibration.py": "from twins.base import fit\n\ndef go():\n    return fit\n",
            "twins/typed.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from twins.quiet import Q\n",
            "twins/quiet.py": "from twins import typed\n",
            "benchmarks/__init__.py": "",
            "benchmarks/scoring.py": "from . import cli\nfrom twins import base\n",
            "benchmarks/cli/__init__.py": "from benchmarks.scoring import *\nfrom sysid.data import record\n",
        },
    )


TOY_FLOORS = (("sysid.data",), ("sysid.signals",), ("sysid.report",))


def test_checker_reports_a_wrong_import(tmp_path):
    _toy_tree(tmp_path)
    bad = layering_violations(import_edges(tmp_path))
    assert bad == [
        "benchmarks/scoring.py:1: benchmarks.scoring imports benchmarks.cli",
        "sysid/data/record.py:2: sysid.data.record imports twins.base",
    ]


def test_checker_reports_a_family_importing_a_higher_one(tmp_path):
    _toy_tree(tmp_path)
    bad = family_violations(import_edges(tmp_path), TOY_FLOORS)
    assert bad == [
        "sysid/signals/gen.py:2: sysid.signals.gen imports sysid.report.figs "
        "(floor 1 sysid.signals -> floor 2 sysid.report)"
    ]
    # the same import is fine once report stands below signals
    assert family_violations(import_edges(tmp_path), (("sysid.data",), ("sysid.report",), ("sysid.signals",))) == []


def test_checker_reports_a_cycle(tmp_path):
    _toy_tree(tmp_path)
    edges = import_edges(tmp_path)
    cycles = import_cycles(edges)
    # base <-> calibration (one side function-local), scoring <-> cli, and typed <-> quiet (one side type-only)
    assert cycles == [
        ["benchmarks.cli", "benchmarks.scoring"],
        ["twins.base", "twins.calibration"],
        ["twins.quiet", "twins.typed"],
    ]
    assert "twins/base.py:4: twins.base imports twins.calibration" in _describe(cycles, edges)[1]


def test_a_package_listing_its_own_modules_is_no_cycle(tmp_path):
    _write(
        tmp_path,
        {
            "sysid/__init__.py": "",
            "sysid/linear/__init__.py": (
                "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from sysid.linear.arx import ARX\n"
            ),
            "sysid/linear/arx.py": "from sysid.linear import order\n",
            "sysid/linear/order.py": "from sysid.linear import arx  # a real cycle\n",
        },
    )
    assert import_cycles(import_edges(tmp_path, ("sysid",))) == [["sysid.linear.arx", "sysid.linear.order"]]
