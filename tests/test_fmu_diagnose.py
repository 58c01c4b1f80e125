"""The diagnosis of a twin made from an FMU (``diagnose --fmu``): the project's own cantilever FMU against the
native twin, on records with an effect hidden by the test; the refusals (no declared range, strings, an FMU
that does not instantiate) and a failed simulation during a trial.

The default suite runs one seed per effect (and the noise-only case) on the kernel route, whose samples equal
the FMU's bit for bit (checked here), on short records; the FMU route end to end and the ten-seed statistics per
effect are ``slow``; a long record through the FMU is timed in ``tests/perf/test_fmu_diagnose_long.py``.
"""

from __future__ import annotations

import math
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")

from fmu_diagnose_cases import CASES, FMU, fmu_case, generic_value, same_cause  # noqa: E402

from sysid.data.record import Record  # noqa: E402
from sysid.errors import ConfigError, DataError  # noqa: E402
from twins.discrepancy import diagnose  # noqa: E402
from twins.external import external_twin_class, fmu_twin_class  # noqa: E402
from twins.external.fmu import FMUCore  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _outcome(effect, seed, route="fmu", n=2000):
    twin, est, val, params, checked = fmu_case(effect, seed, n, route)
    out = diagnose(twin, est, val, max_rounds=1)
    if effect is None:
        return out["verdict"] == "none", out
    top = out["causes"][0] if out["causes"] else {}
    if not same_cause(effect, top, twin):
        return False, out
    errs = [abs(generic_value(twin, top, k) - params[k]) / abs(params[k]) for k in checked]
    return all(math.isfinite(e) and e <= 0.10 for e in errs), out


def test_fmu_twin_simulates_as_the_native_twin():
    from twins.cantilever import CantileverTwin

    cls = fmu_twin_class(FMU, ["gain_um_per_v", "f1_hz"])
    assert cls.name == "fmu:cantilever" and cls.CALIBRATION_PARAMS == ("gain_um_per_v", "f1_hz")
    assert cls.units == {"u": "V", "y": "um"}
    tw = cls.from_options(set_=["effect_measurement_noise=false,effect_sensor_quantization=false,f1_hz=650"])
    native = CantileverTwin.from_options(without=["measurement_noise", "sensor_quantization"], set_=["f1_hz=650"])
    rng = np.random.default_rng(1)
    u = 40 * np.sin(2 * np.pi * 80 * np.arange(1500) / 1e4) + 5 * rng.standard_normal(1500)
    assert np.array_equal(tw.simulate(u, 1e4), native.simulate(u, 1e4))
    # the instance is reused and reset: a second run with other parameters is again the native twin's
    assert np.array_equal(
        tw.with_params(f1_hz=900.0).simulate(u, 1e4), native.with_params(f1_hz=900.0).simulate(u, 1e4)
    )
    # the generic delay wrapped around the FMU is named generic_input_delay_s (the FMU has its own input_delay_s)
    assert cls.EFFECTS["input_delay"].params == {"delay": "generic_input_delay_s"}


def test_fmu_and_kernel_routes_simulate_alike():
    """The configured FMU twin and the kernel route give the same samples, effects included: a diagnosis of one
    is the diagnosis of the other (the default suite runs the kernel route, the slow one both)."""
    for effect in ("input_delay", "sensor_lowpass"):
        fmu, est, _, _, _ = fmu_case(effect, 0, 800, "fmu")
        ker, _, _, _, _ = fmu_case(effect, 0, 800, "kernel")
        for tw_f, tw_k in (
            (fmu, ker),
            (fmu.with_effects(set(fmu.effects) | {effect}), ker.with_effects(set(ker.effects) | {effect})),
        ):
            assert np.array_equal(tw_f.simulate(est.u, est.fs), tw_k.simulate(est.u, est.fs))


@pytest.mark.heavy
@pytest.mark.parametrize("effect", list(CASES) + [None])
def test_hidden_effect_named_as_native_kernel_route(effect):
    """One seed per effect (default suite): the native twin's cause, its parameters within 10 %; noise → none."""
    ok, out = _outcome(effect, 0, "kernel")
    assert ok, (out["verdict"], out["causes"])
    if effect is not None:
        assert out["gain"]["nrmse_ratio"] < 1.0 and out["causes"][0]["p_value"] < 0.01


@pytest.mark.slow
def test_fmu_hidden_delay_named_as_native():
    """End to end through the FMU: the delay named, within 10 %."""
    ok, out = _outcome("input_delay", 0, "fmu")
    assert ok, out["causes"]


@pytest.mark.slow
@pytest.mark.parametrize("route", ["kernel", "fmu"])
@pytest.mark.parametrize("effect", list(CASES) + [None])
def test_hidden_effect_rate(effect, route):
    """At least 9 of 10 seeds: the native twin's cause (its generic origin), parameters within 10 %; noise → none."""
    results = [_outcome(effect, seed, route)[0] for seed in range(10)]
    assert sum(results) >= 9, results


# ------------------------------------------------------------------------------------------ refusals
def _edited_fmu(tmp_path: Path, name: str, edit=None, drop_binaries: bool = False) -> Path:
    out = tmp_path / name
    with zipfile.ZipFile(FMU) as zin, zipfile.ZipFile(out, "w") as zout:
        for item in zin.infolist():
            if drop_binaries and item.filename.startswith("binaries/"):
                continue
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml" and edit is not None:
                data = edit(data.decode("utf-8")).encode("utf-8")
            zout.writestr(item, data)
    return out


def test_fmu_param_without_range_refused(tmp_path):
    def drop_range(xml: str) -> str:
        i = xml.index('name="gain_um_per_v"')
        j = xml.index("/>", i)
        part = xml[i:j]
        for key in ("min", "max"):
            k = part.find(f' {key}="')
            if k >= 0:
                e = part.index('"', k + len(key) + 3)
                part = part[:k] + part[e + 1 :]
        return xml[:i] + part + xml[j:]

    path = _edited_fmu(tmp_path, "norange.fmu", drop_range)
    with pytest.raises(ConfigError, match="declares no range"):
        fmu_twin_class(path, ["gain_um_per_v"])
    with pytest.raises(ConfigError, match="is String"):
        fmu_twin_class(FMU, ["hysteresis"])
    with pytest.raises(ConfigError, match="no parameter 'nope'"):
        fmu_twin_class(FMU, ["nope"])


def test_fmu_string_signal_refused(tmp_path):
    """A String output cannot be compared with a record's column (a String parameter without a start value
    is refused by FMPy's own check of the model description, also one line)."""

    def string_output(xml: str) -> str:
        i = xml.index('name="y"')
        j = xml.index("</ScalarVariable>", i)
        k = xml.index("<Real", i)
        return xml[:k] + '<String start="0"/>' + xml[xml.index("/>", k) + 2 : j] + xml[j:]

    path = _edited_fmu(tmp_path, "stringout.fmu", string_output)
    with pytest.raises(ConfigError, match="output 'y' is a String variable"):
        fmu_twin_class(path, ["gain_um_per_v"])


def test_fmu_that_does_not_instantiate_refused(tmp_path):
    path = _edited_fmu(tmp_path, "nobin.fmu", drop_binaries=True)
    with pytest.raises(ConfigError, match="fails to instantiate"):
        fmu_twin_class(path, ["gain_um_per_v"])


def test_cli_fmu_refusals_one_line(tmp_path):
    rec = Record(u=np.sin(np.arange(500) / 10.0), y=np.cos(np.arange(500) / 10.0), fs=1e4)
    from sysid.data.io import write_record

    data = write_record(rec, tmp_path / "d.npz")
    for extra, words in (
        (["--param", "hysteresis"], "is String"),
        (["--fmu-input", "nope"], "no input variable 'nope'"),
    ):
        cmd = [sys.executable, "-m", "benchmarks.cli", "diagnose", "--fmu", str(FMU), "--data", str(data), *extra]
        r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
        assert r.returncode == 2, r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and words in r.stderr, r.stderr


# ------------------------------------------------------------------------------------------ failures
def test_fmu_failed_run_raises_and_recovers():
    core = FMUCore(FMU)
    params_cls, _ = core.params_class(["gain_um_per_v"])
    p = params_cls(effect_measurement_noise=False, effect_sensor_quantization=False)
    with pytest.raises(DataError, match="simulation failed"):
        core(np.array([0.0, np.nan, 0.0]), 1e4, p, frozenset())  # the slave refuses a non-finite input
    y = core(np.ones(50), 1e4, p, frozenset())  # the instance was re-made
    assert np.all(np.isfinite(y)) and y[-1] > 0


def test_fmpy_route_equals_the_slave_route():
    """The route a model-exchange FMU takes (``fmpy.simulate_fmu`` with the input as a signal table) gives the
    samples of the co-simulation slave route (here both on the co-simulation FMU: no model-exchange FMU ships)."""
    core = FMUCore(FMU)
    params_cls, _ = core.params_class(["gain_um_per_v"])
    p = params_cls(effect_measurement_noise=False, effect_sensor_quantization=False)
    u = 30 * np.sin(2 * np.pi * 90 * np.arange(400) / 1e4)
    y_slave = core(u, 1e4, p, frozenset())
    core.cs = False
    y_fmpy = core(u, 1e4, p, frozenset())
    assert np.max(np.abs(y_fmpy - y_slave)) < 1e-9 * np.max(np.abs(y_slave))


def test_failed_simulation_is_a_failed_trial():
    """A model whose simulation fails for one candidate (its own effect ``stiction``: the solver diverges whenever
    it is on) leaves a row with the error in ``rounds``; the other candidate is tried and the diagnosis ends."""
    from dataclasses import dataclass

    from scipy import signal as sps

    from twins.base import EffectSpec, pfield

    @dataclass
    class P:
        gain: float = pfield(1.0, "1", 0.1, 10.0, "gain")
        tau_s: float = pfield(0.01, "s", 1e-3, 0.1, "time constant")
        stick: float = pfield(0.1, "1", 0.0, 1.0, "stiction level")

    def core(u, fs, p, effects):
        if "stiction" in effects:
            raise RuntimeError("solver diverged")
        a = math.exp(-1 / (fs * p.tau_s))
        return sps.lfilter([p.gain * (1 - a)], [1, -a], u)

    fs = 1000.0
    u = sps.lfilter(*sps.butter(2, 0.2), np.random.default_rng(0).standard_normal(3000))
    W = external_twin_class(
        "failing",
        core,
        P,
        {"stiction": EffectSpec("stiction", "failing", "stick-slip", "dead band", {"level": "stick"})},
        ["gain", "tau_s"],
    )
    truth = W(W.Params(gain=2.0), {"input_delay"}).with_params(input_delay_s=0.004)
    y = truth.simulate(u, fs) + 1e-3 * np.random.default_rng(1).standard_normal(u.size)
    rec = Record(u=u, y=y, fs=fs, source="failing")
    out = diagnose(W(), rec[:1800], rec[1800:], max_rounds=1, candidates=["input_delay", "stiction"])
    assert any(r.get("effect") == "stiction" and "simulation failed" in r.get("error", "") for r in out["rounds"]), out[
        "rounds"
    ]
    assert out["causes"] and out["causes"][0]["effect"] == "input_delay"


def test_cli_fmu_diagnose_json(tmp_path):
    """``diagnose --fmu``: the FMU configured as the native twin that made the record predicts it exactly."""
    import json

    from sysid.data.io import write_record
    from twins.cantilever import CantileverTwin

    tw = CantileverTwin.from_options(without=["measurement_noise", "sensor_quantization"])
    u = 40 * np.sin(2 * np.pi * 60 * np.arange(1200) / 1e4)
    data = write_record(Record(u=u, y=tw.simulate(u, 1e4), fs=1e4), tmp_path / "c.npz")
    cmd = [
        sys.executable,
        "-m",
        "benchmarks.cli",
        "diagnose",
        "--fmu",
        str(FMU),
        "--data",
        str(data),
        "--param",
        "gain_um_per_v",
        "--set",
        "effect_measurement_noise=false,effect_sensor_quantization=false",
        "--max-rounds",
        "0",
        "--json",
    ]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["verdict"] == "none" and out["baseline"]["nrmse_val"] < 1e-12
    assert out["calibration"]["fitted"]["gain_um_per_v"] == pytest.approx(0.3, rel=1e-6)
