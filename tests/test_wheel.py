"""What the wheel ships: the three packages, with benchmarks holding only its library, its data and the CLI
subpackage; nothing of tests/ (the speed suite under tests/perf included)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ("pyproject.toml", "README.md", "LICENSE", "sysid", "twins", "benchmarks", "tests")


def test_package_discovery_leaves_tests_out():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    find = project["tool"]["setuptools"]["packages"]["find"]
    assert sorted(find["include"]) == ["benchmarks*", "sysid*", "twins*"]
    assert not any(p.startswith("tests") for p in find["include"])


def test_wheel_holds_no_tests_and_only_the_benchmark_library_and_cli(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")
    for name in SHIPPED:  # a copy, so that building leaves no build/ or egg-info in the checkout
        (shutil.copytree if (ROOT / name).is_dir() else shutil.copy2)(
            ROOT / name, src / name, **({"ignore": ignore} if (ROOT / name).is_dir() else {})
        )
    out = tmp_path / "dist"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "--no-build-isolation", "-q", "-w", str(out)],
        check=True,
        cwd=tmp_path,
        timeout=600,
    )
    (wheel,) = out.glob("piezotwin-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    modules = [n for n in names if n.endswith(".py")]
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"sysid", "twins", "benchmarks"}
    assert not [n for n in names if n.startswith("tests/") or "/tests/" in n or "/perf/" in n]
    library = {p.relative_to(ROOT).as_posix() for p in (ROOT / "benchmarks").rglob("*.py")}
    shipped_bench = {n for n in modules if n.startswith("benchmarks/")}
    assert shipped_bench == library  # the library and benchmarks/cli, nothing more
    assert "benchmarks/cli/main.py" in shipped_bench and "sysid/data/record.py" in modules
