"""Models given by their equations (``STATES``, ``rates``, ``output``): compiled and integrated against a closed
form, bad models refused with one line (in Python and by the CLI, exit code 2, no traceback), and the extended
model that ``diagnose --save-model`` writes loads and simulates as the diagnosis's final twin."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from inside_cases import MSD_MODEL, msd_case

from sysid.data.io import read_record, write_record
from sysid.errors import ConfigError
from sysid.evaluation.metrics import nrmse
from twins.external import load_model

OSCILLATOR = '''"""A linear oscillator, its state started at rest."""
import math
from dataclasses import dataclass

from twins.base import pfield

STATES = {"x": ("position", "m"), "v": ("velocity", "m/s")}
SUBSTEPS = 8


@dataclass
class Params:
    f0_hz: float = pfield(5.0, "Hz", 0.1, 100.0, "natural frequency")
    zeta: float = pfield(0.1, "1", 0.0, 0.9, "damping ratio")
    gain: float = pfield(2.0, "m/N", 0.01, 10.0, "static gain")


def rates(x, u, p):
    w = 2.0 * math.pi * p.f0_hz
    return (x[1], w * w * (p.gain * u - x[0]) - 2.0 * p.zeta * w * x[1])


def output(x, u, p):
    return x[0]
'''


def _model(tmp_path: Path, text: str, name: str = "user_model") -> Path:
    path = tmp_path / f"{name}.py"
    path.write_text(text)
    return path


def test_linear_oscillator_step_response_matches_the_closed_form(tmp_path):
    """A unit step held from t = 0: x(t) = G·(1 − e^(−ζωt)·(cos ω_d t + ζω/ω_d · sin ω_d t)), ω_d = ω√(1 − ζ²)."""
    cls = load_model(str(_model(tmp_path, OSCILLATOR)))
    twin = cls()
    fs, n = 200.0, 800
    y = twin.simulate(np.ones(n), fs)
    t = np.arange(n) / fs
    w, z, g = 2 * math.pi * 5.0, 0.1, 2.0
    wd = w * math.sqrt(1 - z * z)
    exact = g * (1 - np.exp(-z * w * t) * (np.cos(wd * t) + z * w / wd * np.sin(wd * t)))
    assert np.max(np.abs(y - exact)) < 1e-6 * g


def test_compiled_model_is_fast_enough_for_the_diagnosis(tmp_path):
    """100 k samples in well under a second once compiled (hundreds of trial simulations must fit in minutes)."""
    import time

    cls = load_model(str(_model(tmp_path, OSCILLATOR)))
    twin = cls()
    u = np.random.default_rng(0).standard_normal(100_000)
    twin.simulate(u[:100], 1000.0)  # compile
    t0 = time.process_time()
    y = twin.simulate(u, 1000.0)
    assert np.all(np.isfinite(y)) and time.process_time() - t0 < 2.0


BAD = {
    "does not compile": ('return (x[1], x[0] + "1")', "do not compile with numba"),
    "returns NaN": ("return (x[1], math.nan * x[0])", "NaN"),
    "wrong count": ("return (x[1],)", "returns 1 values for the 2 states"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_bad_equations_are_refused_with_one_line(tmp_path, case):
    body, words = BAD[case]
    text = OSCILLATOR.replace(
        "    w = 2.0 * math.pi * p.f0_hz\n    return (x[1], w * w * (p.gain * u - x[0]) - 2.0 * p.zeta * w * x[1])",
        f"    {body}",
    )
    with pytest.raises(ConfigError) as exc:
        load_model(str(_model(tmp_path, text, "bad_" + case.replace(" ", "_"))))
    assert words in str(exc.value) and "\n" not in str(exc.value)


def test_unknown_state_role_is_refused_with_the_valid_ones(tmp_path):
    text = OSCILLATOR.replace('("velocity", "m/s")', '("speed", "m/s")')
    with pytest.raises(ConfigError, match="role 'speed', not a known role; valid: position, velocity"):
        load_model(str(_model(tmp_path, text, "bad_role")))


@pytest.fixture(scope="module")
def cubic_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("eqcli")
    est, val, truth = msd_case("cubic", 0)
    write_record(est, d / "est.npz")
    write_record(val, d / "val.npz")
    (d / "msd.py").write_text(MSD_MODEL)
    return d, truth


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "benchmarks.cli", "diagnose", *args], capture_output=True, text=True)


@pytest.mark.parametrize("case", ["does not compile", "returns NaN", "unknown role"])
def test_cli_refuses_a_bad_model_with_exit_2_and_one_line(cubic_files, case):
    d, _ = cubic_files
    if case == "unknown role":
        text = MSD_MODEL.replace('("velocity", "m/s")', '("speed", "m/s")')
    else:
        body = BAD[case][0]
        text = MSD_MODEL.replace(
            "    w = 2.0 * math.pi * p.f0_hz\n    return (x[1], w * w * (p.gain * u - x[0]) - 2.0 * p.zeta * w * x[1])",
            f"    {body}",
        )
    bad = d / f"bad_{case.replace(' ', '_')}.py"
    bad.write_text(text)
    r = _cli("--model", str(bad), "--data", str(d / "est.npz"), "--val", str(d / "val.npz"), "-q")
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "model" in lines[0], r.stderr


@pytest.mark.heavy
def test_save_model_round_trip(cubic_files, tmp_path):
    """``diagnose --model --save-model``: the cubic spring is named, and the written model loads and simulates the
    validation record as the diagnosis's extended twin (its NRMSE as reported, to 1e-6)."""
    d, truth = cubic_files
    out = tmp_path / "extended.py"
    r = _cli(
        "--model",
        str(d / "msd.py"),
        "--data",
        str(d / "est.npz"),
        "--val",
        str(d / "val.npz"),
        "--max-rounds",
        "1",
        "--save-model",
        str(out),
        "--json",
        "-q",
    )
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert [c["effect"] for c in res["causes"]] == ["cubic_spring@x"]
    assert res["causes"][0]["params"]["cubic_spring_x_k3"] == pytest.approx(truth["k3"], rel=0.1)
    assert "STATES" in out.read_text()
    ext = load_model(str(out))()
    val = read_record(d / "val.npz")
    assert nrmse(val.y, ext.simulate(val.u, val.fs)) == pytest.approx(res["extended"]["nrmse_val"], abs=1e-6)


def test_periodic_start_matches_the_steady_state_sine_response(tmp_path):
    """A record of whole periods of a sine in steady state (as a benchmark's multisine test is given): started in
    its periodic steady state, the oscillator gives x = G·|H|·sin(ωt + ∠H) with H = ω₀²/(ω₀² − ω² + 2jζω₀ω) from
    the first sample on; started at rest it does not (the transient)."""
    text = OSCILLATOR.replace("SUBSTEPS = 8", 'SUBSTEPS = 8\nINPUT = "cubic"')
    twin = load_model(str(_model(tmp_path, text)))()
    fs, f, n = 200.0, 4.0, 400  # 8 whole periods
    t = np.arange(n) / fs
    u = np.sin(2 * math.pi * f * t)
    w0, w, z, g = 2 * math.pi * 5.0, 2 * math.pi * f, 0.1, 2.0
    h = w0**2 / (w0**2 - w**2 + 2j * z * w0 * w)
    exact = g * abs(h) * np.sin(w * t + np.angle(h))
    assert np.max(np.abs(twin.simulate_periodic(u, fs) - exact)) < 1e-4 * g
    assert np.max(np.abs(twin.simulate(u, fs) - exact)) > 0.1 * g


TANK = '''"""One tank by Torricelli's law, filled by a pump."""
import math
from dataclasses import dataclass

from twins.base import pfield

STATES = {"h": ("level", "m")}
INPUT = "hold"


@dataclass
class Params:
    k1: float = pfield(0.2, "m^0.5/s", 1e-3, 1.0, "outflow coefficient")
    k4: float = pfield(0.1, "m/(V s)", 1e-3, 1.0, "pump gain")


def rates(x, u, p):
    return (p.k4 * u - p.k1 * math.sqrt(max(x[0], 0.0)),)


def output(x, u, p):
    return x[0]
'''


@pytest.mark.heavy
@pytest.mark.parametrize("c, beta", [(0.05, 1.0), (-0.02, 0.8), (0.08, 0.0)])
def test_power_outflow_settles_where_the_flows_balance(tmp_path, c, beta):
    """``power_outflow@h`` adds −c·h^β to the level's rate: under a constant pump the level settles where
    k4·u = k1·√h + c·h^β (the root by brentq), and the model ``--save-model`` writes with it simulates the same."""
    from scipy.optimize import brentq

    from twins.equations.writer import write_model

    twin = load_model(str(_model(tmp_path, TANK, "tank")))()
    ext = twin.with_effects(set(twin.effects) | {"power_outflow@h"}).with_params(
        power_outflow_h_c=c, power_outflow_h_beta=beta
    )
    u = np.full(4000, 3.0)
    y = ext.simulate(u, 1.0)
    level = brentq(lambda h: 0.1 * 3.0 - 0.2 * math.sqrt(h) - c * h**beta, 1e-9, 100.0)
    assert y[-1] == pytest.approx(level, rel=1e-6)
    assert abs(y[-1] - 2.25) > 0.05  # the model's own level, 2.25 m, is not where the extended one settles
    out = write_model(ext, tmp_path / "tank_extended.py")
    assert "laws.power_outflow(" in out.read_text()
    again = load_model(str(out))()
    assert np.allclose(again.simulate(u, 1.0), y, rtol=0, atol=1e-9)
