"""The Torricelli two-tank model as a user's pythonfmu FMU: it gives the Python model's samples, declares its own
effect behind a switch, and the refusals of --fmu-effect; the diagnosis' spread starts and joint (pair) trials.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sysid.data.io import write_record
from sysid.data.record import Record
from sysid.errors import ConfigError

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def tanks_fmu(tmp_path_factory) -> Path:
    from benchmarks.examples.cascaded_tanks_fmu import build_tanks_fmu

    return build_tanks_fmu(tmp_path_factory.mktemp("fmu") / "tanks.fmu")


def _pump(n: int = 600, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.repeat(rng.uniform(1.0, 7.0, n // 30 + 1), 30)[:n]


def test_fmu_gives_the_python_models_samples(tanks_fmu):
    """Same law, same integrator: the FMU's samples equal the Python model's, with and without its overflow."""
    from benchmarks.examples import cascaded_tanks as ct
    from twins.external import fmu_twin_class

    cls = fmu_twin_class(tanks_fmu, effects={"overflow": ["x1_max", "overflow_share"]})
    # the effect's parameters leave the default calibration set
    assert cls.CALIBRATION_PARAMS == ("k1", "k2", "k3", "k4", "x1_0", "x2_0")
    assert "overflow" in cls.EFFECTS and cls.EFFECTS["overflow"].params == {
        "x1_max": "x1_max",
        "overflow_share": "overflow_share",
    }
    u = _pump()
    plain = cls().simulate(u, 0.25)
    np.testing.assert_allclose(plain, ct.simulate(u, 0.25, ct.Params()), rtol=0, atol=1e-12)
    over = cls(effects={"overflow"}).with_params(x1_max=6.0, overflow_share=0.3).simulate(u, 0.25)
    ref = ct.simulate(u, 0.25, ct.Params(x1_max=6.0, overflow_share=0.3), frozenset({"overflow"}))
    np.testing.assert_allclose(over, ref, rtol=0, atol=1e-12)
    assert np.max(np.abs(over - plain)) > 0.1  # the switch acts


def test_fmu_effect_refusals(tanks_fmu, tmp_path):
    from twins.external import fmu_twin_class

    with pytest.raises(ConfigError, match="Boolean parameter effect_leak"):
        fmu_twin_class(tanks_fmu, effects={"leak": ["k1"]})
    with pytest.raises(ConfigError, match="no Real parameter 'nope'"):
        fmu_twin_class(tanks_fmu, effects={"overflow": ["nope"]})
    with pytest.raises(ConfigError, match="substeps"):  # an Integer, not a ranged Real
        fmu_twin_class(tanks_fmu, effects={"overflow": ["substeps"]})
    data = tmp_path / "est.npz"
    write_record(Record(u=_pump(), y=np.linspace(4, 6, 600), fs=0.25), data)
    for bad in ("overflow", "overflow=", "=x1_max"):
        r = subprocess.run(
            [
                sys.executable,
                "-m",
                "benchmarks.cli",
                "diagnose",
                "--fmu",
                str(tanks_fmu),
                "--data",
                str(data),
                "--fmu-effect",
                bad,
            ],
            capture_output=True,
            text=True,
            cwd=ROOT,
        )
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "--fmu-effect" in r.stderr, r.stderr
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "benchmarks.cli",
            "diagnose",
            "cantilever",
            "--data",
            str(data),
            "--fmu-effect",
            "overflow=x1_max",
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 2 and "go with --fmu" in r.stderr


def test_spread_starts_cover_the_ranges():
    """j/N of each numeric range (geometric over more than two decades), the rest as first fitted."""
    import dataclasses

    from twins.discrepancy.candidates import spread_starts
    from twins.paramfields import pfield

    @dataclasses.dataclass
    class P:
        a: float = pfield(0.0, "V", -3.0, 3.0, "linear range")
        b: float = pfield(1.0, "s", 1e-3, 1e3, "six decades")
        n: int = pfield(2, "1", 1, 8, "an integer")

    class Tw:
        params = P()

    class Tr:
        twin = Tw()
        effect_params = {"a": 0.1, "b": 2.0, "n": 2}

    pts = spread_starts(Tr(), 3)  # type: ignore[arg-type]
    assert len(pts) == 2 and spread_starts(Tr(), 1) == []  # type: ignore[arg-type]
    assert [p["a"] for p in pts] == pytest.approx([-1.0, 1.0])
    assert [p["b"] for p in pts] == pytest.approx([1e-3 * 1e6 ** (1 / 3), 1e-3 * 1e6 ** (2 / 3)])
    assert all(p["n"] == 2 for p in pts)
