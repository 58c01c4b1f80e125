"""The CLI starts at once: a command imports the heavy libraries (scipy.signal, torch, Dask, matplotlib, numba)
only when it uses them. Checked on the import graph in a fresh interpreter, not on a time: which modules are in
``sys.modules`` after the command ran."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

# Packages whose import costs 0.2-1.5 s each on the 2-core machine (python -X importtime).
HEAVY = (
    "scipy.signal",
    "scipy.stats",
    "scipy.optimize",
    "torch",
    "dask",
    "distributed",
    "matplotlib",
    "numba",
    "optuna",
    "fmpy",
    "h5py",
    "jinja2",
)

_PROBE = """
import json, sys
from benchmarks.cli import main
try:
    rc = main(sys.argv[2:])
except SystemExit as exc:
    rc = exc.code
with open(sys.argv[1], "w") as f:
    json.dump({"rc": rc, "modules": sorted(sys.modules)}, f)
"""


def _loaded(tmp_path: Path, args: list[str]) -> tuple[int, set[str]]:
    """Run ``piezotwin ARGS`` in a fresh interpreter; its exit code and the modules it had imported."""
    report = tmp_path / "modules.json"
    proc = subprocess.run(
        [sys.executable, "-c", _PROBE, str(report), *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert report.exists(), proc.stderr
    data = json.loads(report.read_text())
    return data["rc"], set(data["modules"])


def _heavy(modules: set[str]) -> list[str]:
    return sorted(h for h in HEAVY if h in modules or any(m.startswith(h + ".") for m in modules))


@pytest.fixture
def tiny_csv(tmp_path: Path) -> Path:
    path = tmp_path / "tiny.csv"
    path.write_text("t,u,y\n" + "".join(f"{k * 1e-3:g},{k + 1},{2 * k + 1}\n" for k in range(5)))
    return path


@pytest.mark.parametrize("args", [["--version"], ["--help"], ["preprocess", "--help"]])
def test_parser_alone_imports_nothing_heavy(tmp_path, args):
    rc, modules = _loaded(tmp_path, args)
    assert rc == 0
    assert _heavy(modules) == []
    assert "scipy" not in modules and "pandas" not in modules  # building the parser needs neither


@pytest.mark.parametrize("step", [["--remove-offset"], ["--detrend"], ["--segment", "2"]])
def test_preprocess_without_filters_imports_nothing_heavy(tmp_path, tiny_csv, step):
    """The steps that are arithmetic on the samples: no scipy.signal (1.4 s of a 1.8 s run before), no numba."""
    out = tmp_path / "x.npz"
    rc, modules = _loaded(tmp_path, ["preprocess", str(tiny_csv), *step, "-o", str(out)])
    assert rc == 0 and out.exists()
    assert _heavy(modules) == []


def test_filtering_steps_still_import_what_they_use(tmp_path, tiny_csv):
    """The probe sees a lazy import when it happens: a band-pass loads scipy.signal and gives its result."""
    import numpy as np

    out = tmp_path / "x.npz"
    rc, modules = _loaded(tmp_path, ["preprocess", str(tiny_csv), "--bandpass", "20:200:2", "-o", str(out)])
    assert rc == 0, modules
    assert "scipy.signal" in modules
    with np.load(out, allow_pickle=False) as z:
        assert z["y"].shape == (5,) and np.all(np.isfinite(z["y"]))
