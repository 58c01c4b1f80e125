"""House rules that keep the code readable, checked on the source tree: module sizes, the length of the
diagnosis pipeline's functions, and comments that explain in the code's own terms (no issue numbers, no
documents outside the project)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("sysid", "twins", "benchmarks")
MAX_MODULE_LINES = 600
MAX_DIAGNOSIS_MODULE_LINES = 400
MAX_DIAGNOSIS_FUNCTION_LINES = 80
CITATION = re.compile(r"\b[Ii]ssues? ?#?\d+\b|DESIGN\.md|STYLE\.md")


def _modules(*roots: str) -> list[Path]:
    return sorted(p for r in roots for p in (REPO / r).rglob("*.py"))


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_no_module_over_the_limit():
    big = {str(p.relative_to(REPO)): _lines(p) for p in _modules(*PACKAGES) if _lines(p) > MAX_MODULE_LINES}
    assert big == {}


def test_diagnosis_pipeline_is_small_pieces():
    root = REPO / "twins" / "discrepancy"
    big = {str(p.relative_to(REPO)): _lines(p) for p in root.rglob("*.py") if _lines(p) > MAX_DIAGNOSIS_MODULE_LINES}
    assert big == {}
    long_functions = {}
    for path in root.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_DIAGNOSIS_FUNCTION_LINES:
                    long_functions[f"{path.relative_to(REPO)}:{node.name}"] = n
    assert long_functions == {}


def test_comments_do_not_cite_issues_or_outside_documents():
    files = _modules(*PACKAGES, "tests") + [REPO / "Makefile", REPO / ".ci" / "run", REPO / "pyproject.toml"]
    files += sorted((REPO / "benchmarks" / "settings").rglob("*.toml"))
    hits = [
        f"{p.relative_to(REPO)}:{i}: {line.strip()}"
        for p in files
        if p != Path(__file__)
        for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
        if CITATION.search(line)
    ]
    assert hits == []


MAX_DOCSTRING_LINES = 29


def test_docstrings_say_contract_reason_and_reference_in_under_30_lines():
    """A docstring says what the code does, its contract and why, with the paper's reference; how a number was
    measured goes to the docs page of that topic (docs/development.md)."""
    long = {}
    for p in _modules(*PACKAGES):
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                doc = ast.get_docstring(node, clean=False)
                if doc and len(doc.splitlines()) > MAX_DOCSTRING_LINES:
                    long[f"{p.relative_to(REPO)}:{getattr(node, 'name', '<module>')}"] = len(doc.splitlines())
    assert long == {}
