"""The documentation stays true: README short, every relative link resolves, every ``python`` example in
docs/ runs, the CLI reference equals what the parser generates, and the licence is declared."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]

# Pages linked from the README or docs/index.md before they are written (work in progress on another branch);
# allowed to be missing only while listed here. Empty in a release.
PENDING = {}

_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
_FENCE = re.compile(r"^```[^\n]*\n.*?^```", re.S | re.M)


def _links(page: Path) -> list[str]:
    text = _FENCE.sub("", page.read_text(encoding="utf-8"))  # code blocks hold no links
    text = re.sub(r"`[^`\n]*`", "", text)
    return _LINK.findall(text)


def test_readme_is_short():
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 150


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    missing = []
    for target in _links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
            continue  # http(s), mailto: not checked offline; anchors within the page
        path = (page.parent / target.split("#")[0]).resolve()
        if not path.exists() and path.name not in PENDING:
            missing.append(target)
    assert missing == [], f"{page.relative_to(ROOT)}: broken links {missing}"


def test_link_check_can_fail(tmp_path):
    page = tmp_path / "p.md"
    page.write_text("see [x](nowhere.md) and `[not](a-link.md)` and [web](https://example.org)\n")
    assert _links(page) == ["nowhere.md", "https://example.org"]


def _python_blocks(page: Path) -> list[tuple[int, str]]:
    """(line, code) of every ```python block not preceded by a ``<!-- docs-test: skip (...) -->`` line."""
    lines = page.read_text(encoding="utf-8").splitlines()
    out, i = [], 0
    while i < len(lines):
        if lines[i].strip() == "```python":
            skip = i > 0 and lines[i - 1].strip().startswith("<!-- docs-test: skip")
            j = i + 1
            while lines[j].strip() != "```":
                j += 1
            if not skip:
                out.append((i + 1, "\n".join(lines[i + 1 : j])))
            i = j
        i += 1
    return out


DOC_EXAMPLES = [p for p in PAGES if _python_blocks(p)]


@pytest.mark.parametrize("page", DOC_EXAMPLES, ids=lambda p: str(p.relative_to(ROOT)))
def test_python_examples_run(page, tmp_path, monkeypatch):
    """The blocks of one page run in order in one namespace (later blocks use earlier names), from the repo root."""
    import logging

    monkeypatch.chdir(ROOT)
    loggers = [logging.getLogger(n) for n in ("", "sysid", "twins", "benchmarks")]
    saved = [(lg, lg.level, list(lg.handlers)) for lg in loggers]  # examples may configure logging
    namespace: dict = {"__name__": "__docs__"}
    try:
        for line, code in _python_blocks(page):
            exec(compile(code, f"{page.relative_to(ROOT)}:{line}", "exec"), namespace)
    finally:
        for lg, level, handlers in saved:
            lg.setLevel(level)
            lg.handlers[:] = handlers


def test_every_skipped_example_says_why():
    for page in PAGES:
        for m in re.finditer(r"<!-- docs-test: skip(.*?)-->", page.read_text(encoding="utf-8")):
            assert m.group(1).strip(" ()"), f"{page.name}: a skipped example without a reason"


def test_cli_reference_is_generated_from_the_parser():
    """docs/cli.md must equal the generator's output: after adding or changing a command, run `make docs`."""
    from benchmarks.cli.clidoc import generate

    committed = (DOCS / "cli.md").read_text(encoding="utf-8")
    assert committed == generate(), (
        "docs/cli.md is stale: run `make docs` (python -m benchmarks.cli.clidoc -o docs/cli.md)"
    )


def test_cli_reference_lists_every_command_and_option():
    from benchmarks.cli import build_parser
    from benchmarks.cli.clidoc import generate

    text = generate()
    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    for name, p in sub.choices.items():
        assert f"## piezotwin {name}\n" in text
        for a in p._actions:
            for opt in a.option_strings:
                if opt not in ("-h", "--help", "--version", "-q", "--quiet", "-v", "--verbose"):
                    assert f"`{opt}" in text, (name, opt)


def test_licence_declared():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "MIT" and meta["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in text
    # every vendored dataset appears in the data-licence table, with its SOURCE.txt
    table = (DOCS / "data-licences.md").read_text()
    for source in (ROOT / "benchmarks" / "data").glob("*/SOURCE.txt"):
        assert f"`{source.parent.name}`" in table, source.parent.name
