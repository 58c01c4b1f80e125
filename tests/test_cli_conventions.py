"""CLI conventions of every command: --version, -q/--quiet, -v/--verbose through
logging, one-line warnings, progress bars only on a terminal, and a library that never prints or configures
logging itself."""

from __future__ import annotations

import ast
import logging
import subprocess
import sys
import warnings
from importlib.metadata import version
from pathlib import Path

import pytest

from benchmarks.cli import main

ROOT = Path(__file__).resolve().parents[1]


def test_version(capsys):
    for argv in (["--version"], ["list", "--version"]):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 0
        assert capsys.readouterr().out.strip() == f"piezotwin {version('piezotwin')}"


@pytest.fixture
def chatty(monkeypatch):
    """`list` replaced by a command that logs at every level, warns (a multi-line warning) and prints a result."""
    import benchmarks.cli.list_cmd as list_cmd

    def run(args):
        log = logging.getLogger("sysid.fake")
        log.debug("debug detail")
        log.info("working on it")
        warnings.warn("dependency says something\nover two lines", UserWarning, stacklevel=1)
        print("RESULT 42")
        return 0

    monkeypatch.setattr(list_cmd, "run", run)
    warnings.resetwarnings()  # the default filter would show a warning only once per location


@pytest.mark.parametrize(
    "argv, err",
    [
        (["list", "twins"], ["working on it", "warning: UserWarning: dependency says something"]),
        (["-q", "list", "twins"], []),
        (["list", "twins", "--quiet"], []),
        (["list", "twins", "-v"], ["debug detail", "working on it", "warning: UserWarning: dependency says something"]),
    ],
)
def test_quiet_prints_only_results_and_verbose_adds_debug(chatty, capsys, argv, err):
    root_handlers = list(logging.getLogger().handlers)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        assert main(argv) == 0
    out, stderr = capsys.readouterr()
    assert out == "RESULT 42\n"
    assert stderr.splitlines() == err  # one line per message, warnings included
    assert logging.getLogger().handlers == root_handlers  # the CLI puts logging back as it was


def test_progress_bars_only_on_a_terminal(capsys):
    from sysid.progress import enabled, progress, set_enabled

    assert not enabled()  # stderr is captured here, not a terminal
    assert list(progress(range(3), desc="x")) == [0, 1, 2]
    assert capsys.readouterr().err == ""
    previous = set_enabled(False)
    try:
        assert progress(range(3)).disable
    finally:
        set_enabled(previous)


def test_importing_the_library_configures_no_logging():
    code = (
        "import logging, sysid, twins, benchmarks, sysid.registry, twins.registry, benchmarks.scoring, "
        "benchmarks.mainjob, twins.discrepancy\n"
        "r = logging.getLogger()\n"
        "names = [n for n in logging.root.manager.loggerDict if n.split('.')[0] in ('sysid', 'twins', 'benchmarks')]\n"
        "assert not r.handlers and r.level == logging.WARNING, (r.handlers, r.level)\n"
        "assert all(logging.getLogger(n).level == logging.NOTSET and not logging.getLogger(n).handlers\n"
        "           for n in names), names\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]


def _prints_outside_main(path: Path) -> list[int]:
    """Lines of print() calls not inside a function called ``main`` or an ``if __name__ == "__main__"`` block."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    allowed: set[int] = set()
    for node in ast.walk(tree):
        in_main = isinstance(node, ast.FunctionDef) and node.name == "main"
        in_main |= isinstance(node, ast.If) and "__main__" in ast.unparse(node.test)
        if in_main:
            allowed |= {n.lineno for n in ast.walk(node) if hasattr(n, "lineno")}
    return [
        n.lineno
        for n in ast.walk(tree)
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id == "print" and n.lineno not in allowed
    ]


def test_library_logs_never_prints():
    """Only the CLI (benchmarks/cli/main.py, benchmarks/cli/) and scripts' main() print; the speed suite is tests."""
    offenders = {}
    for pkg in ("sysid", "twins", "benchmarks"):
        for path in (ROOT / pkg).rglob("*.py"):
            rel = path.relative_to(ROOT).as_posix()
            if rel == "benchmarks/cli/main.py" or rel.startswith(("benchmarks/cli/", "tests/perf/")):
                continue
            lines = _prints_outside_main(path)
            if lines:
                offenders[rel] = lines
    assert offenders == {}


def test_print_check_can_fail(tmp_path):
    f = tmp_path / "m.py"
    f.write_text("def f():\n    print('x')\n\ndef main():\n    print('ok')\n")
    assert _prints_outside_main(f) == [2]
