"""FMU export (issue 9): build, validate, round trip against the native twins, tunable parameters.

The exporter is exercised on small twins defined in ``tests/_fmu_toy.py`` (a stepped toy and an
FFT-simulated echo channel like the acoustic twin) and on the project's cantilever and acoustic twins.
Inputs are short: fmpy costs tens of microseconds per communication step.
"""

import json
import os
import subprocess
import sys
import zipfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy.validation import validate_fmu  # noqa: E402

from twins.fmu import export_fmu  # noqa: E402
from twins.fmu.check import fmu_simulate, relative_rms  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _fmu_toy import EchoTwin, ToyTwin  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def _md(path):
    with zipfile.ZipFile(path) as z:
        return ET.fromstring(z.read("modelDescription.xml")), json.loads(z.read("resources/piezotwin_fmu.json"))


def _var(root, name):
    for sv in root.iter("ScalarVariable"):
        if sv.get("name") == name:
            return sv
    raise KeyError(name)


# ---------------------------------------------------------------------------------------------- toy twin
@pytest.fixture(scope="module")
def toy_fmu(tmp_path_factory):
    twin = ToyTwin.from_options(set_=["gain=3"], seed=7)
    path = export_fmu(twin, tmp_path_factory.mktemp("toy") / "toy.fmu", fs=1000.0)
    return twin, path


def _toy_input(n=300, fs=1000.0):
    t = np.arange(n) / fs
    return 4.0 * np.sin(2 * np.pi * 7 * t) + np.sign(np.sin(2 * np.pi * 3 * t))


def test_toy_fmu_validates_and_declares_parameters(toy_fmu):
    twin, path = toy_fmu
    assert validate_fmu(str(path)) == []
    root, cfg = _md(path)
    gain = _var(root, "gain")
    assert gain.get("causality") == "parameter" and gain.get("variability") == "fixed"
    real = gain.find("Real")
    assert (real.get("unit"), real.get("min"), real.get("max"), float(real.get("start"))) == ("um/V", "0", "10", 3.0)
    assert [u.get("name") for u in root.iter("Unit")] == sorted({"um/V", "s", "um", "V", "Hz"})
    assert _var(root, "order").find("Integer").get("start") == "1"
    assert _var(root, "weights").find("String").get("start") == "1.0-0.5"
    assert "one of: water, oil" in _var(root, "fluid").get("description")
    assert _var(root, "effect_lag").find("Boolean").get("start") == "true"
    assert _var(root, "effect_offset").find("Boolean").get("start") == "false"
    assert _var(root, "seed").find("Integer").get("start") == "7"
    assert float(_var(root, "fs").find("Real").get("start")) == 1000.0
    y = _var(root, "y")
    assert (y.get("causality"), y.get("initial")) == ("output", "exact")
    assert float(root.find("DefaultExperiment").get("stepSize")) == pytest.approx(1e-3, rel=1e-15)
    assert cfg["core"] == {"kind": "stepper"} and cfg["config"]["seed"] == 7


def test_toy_round_trip_is_exact_with_noise(toy_fmu):
    twin, path = toy_fmu
    u = _toy_input()
    y = fmu_simulate(path, u, 1000.0)
    ref = twin.simulate(u, 1000.0)
    assert np.array_equal(y, ref)  # same stepper, same noise draws, same input samples
    # the noise is really on: another seed gives another output, matching the native twin with that seed
    y9 = fmu_simulate(path, u, 1000.0, start_values={"seed": 9})
    ref9 = ToyTwin(twin.params, twin.effects, 9).simulate(u, 1000.0)
    assert np.array_equal(y9, ref9) and not np.array_equal(y9, y)


@pytest.mark.parametrize("start,change", [
    ({"tau_s": 0.05}, dict(params={"tau_s": 0.05})),
    ({"order": 3, "weights": "0.2;-1.5"}, dict(params={"order": 3, "weights": [0.2, -1.5]})),
    ({"fluid": "oil"}, dict(params={"fluid": "oil"})),
    ({"effect_offset": True, "offset_um": -1.25, "effect_measurement_noise": False},
     dict(params={"offset_um": -1.25}, effects={"lag", "offset"})),
])
def test_toy_start_values_act_as_in_native_twin(toy_fmu, start, change):
    twin, path = toy_fmu
    u = _toy_input(200)
    native = twin.with_params(**change["params"])
    if "effects" in change:
        native = native.with_effects(change["effects"])
    ref = native.simulate(u, 1000.0)
    y = fmu_simulate(path, u, 1000.0, start_values=start)
    assert np.array_equal(y, ref)
    assert not np.allclose(ref, twin.simulate(u, 1000.0))  # the change matters


def test_toy_bad_parameter_and_step_refused(toy_fmu):
    import fmpy

    twin, path = toy_fmu
    with pytest.raises(Exception, match="ExitInitializationMode|fmi2"):
        fmu_simulate(path, _toy_input(10), 1000.0, start_values={"fluid": "honey"})
    # a communication step that is not a whole number of sampling periods
    with pytest.raises(Exception, match="DoStep|fmi2"):
        fmpy.simulate_fmu(str(path), stop_time=0.01, output_interval=1.5e-3)
    # a whole number of periods: the input is held over the step (n samples of the same u)
    res = fmpy.simulate_fmu(str(path), stop_time=0.02, output_interval=2e-3, output=["y"],
                            start_values={"effect_measurement_noise": False},
                            input=np.array([(0.0, 1.0), (1.0, 1.0)], dtype=[("time", float), ("u", float)]))
    ref = twin.with_effects({"lag"}).simulate(np.ones(20), 1000.0)
    assert np.allclose(res["y"][1:], ref[1::2], rtol=0, atol=1e-12)


def test_shipped_code_runs_without_the_project_on_the_path(toy_fmu, tmp_path):
    """The FMU carries twins/ and sysid/ and runs them: pythonfmu puts resources/ first on sys.path, so a
    fresh process uses the shipped copy even where another copy of the project is installed."""
    twin, path = toy_fmu
    u = _toy_input(100)
    np.save(tmp_path / "u.npy", u)
    code = (
        "import importlib.util, sys, numpy as np, fmpy\n"
        "spec = importlib.util.find_spec('twins')\n"
        "print('before', spec.origin if spec else None)\n"
        "u = np.load('u.npy'); n = len(u); t = np.arange(n + 1) * (1.0 / 1000.0)\n"
        "sig = np.zeros(n + 1, dtype=[('time', float), ('u', float)]); sig['time'] = t; sig['u'][:n] = u\n"
        f"r = fmpy.simulate_fmu({str(path)!r}, stop_time=n / 1000.0, output_interval=1e-3, input=sig, output=['y'])\n"
        "np.save('y.npy', r['y'][1:])\n"
        "print('used', sys.modules['twins'].__file__)\n")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    used = proc.stdout.split("used ")[1].strip()
    assert Path(used).parts[-3:] == ("resources", "twins", "__init__.py") and not used.startswith(str(REPO))
    assert np.array_equal(np.load(tmp_path / "y.npy"), twin.simulate(u, 1000.0))


def test_many_instances_in_one_process(toy_fmu):
    """pythonfmu 0.7's loader drops a reference to the slave module per instance (see export.slave_source)."""
    _, path = toy_fmu
    u = _toy_input(5)
    first = fmu_simulate(path, u, 1000.0)
    for _ in range(12):
        assert np.array_equal(fmu_simulate(path, u, 1000.0), first)


# ---------------------------------------------------------------------------------- FFT twin (echo toy)
@pytest.fixture(scope="module")
def echo_fmu(tmp_path_factory):
    twin = EchoTwin()
    return twin, export_fmu(twin, tmp_path_factory.mktemp("echo") / "echo.fmu")


def _burst(fs, n, f0=0.6e6, f1=1.6e6):
    t = np.arange(n) / fs
    return 2.0 * np.sin(2 * np.pi * (f0 * t + 0.5 * (f1 - f0) * fs / n * t * t))


def test_response_core_round_trip(echo_fmu):
    twin, path = echo_fmu
    assert validate_fmu(str(path)) == []
    _, cfg = _md(path)
    core = cfg["core"]
    assert core["kind"] == "response" and core["accuracy"]["relative_rms"] < 1e-4
    fs = 100e6
    u = _burst(fs, 8000)  # past the first arrival (2000 samples) and the echo (6000)
    y = fmu_simulate(path, u, fs)
    ref = twin.simulate(u, fs)  # with its seeded noise
    quiet = twin.with_effects({"echo"}).simulate(u, fs)
    signal = np.sqrt(np.mean(quiet ** 2))
    assert relative_rms(y, ref) < 1e-4
    # the noise drawn per sample in the FMU is the native sequence: the error is far below the noise
    # (independent draws would leave sqrt(2) x noise_v)
    assert np.sqrt(np.mean((y - ref) ** 2)) < 0.05 * twin.params.noise_v < signal


def test_response_core_parameter_change_refits(echo_fmu):
    twin, path = echo_fmu
    fs = 100e6
    u = _burst(fs, 4000)
    start = {"delay_s": 10e-6, "q": 8.0, "effect_measurement_noise": False}
    y = fmu_simulate(path, u, fs, start_values=start)
    native = twin.with_params(delay_s=10e-6, q=8.0).with_effects({"echo"})
    ref = native.simulate(u, fs)
    assert relative_rms(y, ref) < 1e-4
    assert relative_rms(twin.with_effects({"echo"}).simulate(u, fs), ref) > 0.5


def test_response_core_step_equals_vectorised_fir():
    from twins.fmu.response import ResponseCore, fir_apply, impulse_response, sparse_segments

    twin = EchoTwin(effects={"echo"})
    fs = 100e6
    h = impulse_response(twin, fs)
    segs, dropped = sparse_segments(h, energy_tol=1e-8)
    assert 0 < dropped <= 1e-8 and len(segs) == 2  # direct arrival and echo; the flight time costs nothing
    u = _burst(fs, 7000)
    core = ResponseCore(segs, twin.amplifier, None, fs)
    y = np.array([core.step(float(v)) for v in u])
    assert np.allclose(y, fir_apply(segs, twin.amplifier(u)), rtol=0, atol=1e-12 * np.max(np.abs(y)))


# ------------------------------------------------------------------------------------- cantilever twin
@pytest.fixture(scope="module")
def cantilever_fmu(tmp_path_factory):
    from twins.cantilever import CantileverTwin

    twin = CantileverTwin()  # default configuration, measurement noise on, seed 0
    return twin, export_fmu(twin, tmp_path_factory.mktemp("cant") / "cantilever.fmu")


@pytest.fixture(scope="module")
def multisine_head():
    from twins.cantilever import CantileverTwin

    rec = CantileverTwin().generate("thesis-multisine")
    return rec.u[:1500], rec.fs


def test_cantilever_fmu_round_trip(cantilever_fmu, multisine_head):
    twin, path = cantilever_fmu
    assert validate_fmu(str(path)) == []
    u, fs = multisine_head
    assert fs == 10e3
    y = fmu_simulate(path, u, fs)
    ref = twin.simulate(u, fs)
    assert relative_rms(y, ref) <= 1e-9
    root, _ = _md(path)
    assert _var(root, "gain_um_per_v").find("Real").get("unit") == "um/V"
    assert _var(root, "hysteresis").find("String").get("start") == "bouc-wen"


@pytest.mark.parametrize("start,params,effects", [
    ({"bw_alpha": 0.45, "f1_hz": 900.0}, {"bw_alpha": 0.45, "f1_hz": 900.0}, None),
    ({"hysteresis": "prandtl-ishlinskii"}, {"hysteresis": "prandtl-ishlinskii"}, None),
    ({"effect_input_delay": True, "effect_measurement_noise": False}, {}, "+input_delay-measurement_noise"),
    ({"seed": 3}, {}, "seed"),
])
def test_cantilever_tunable_parameters_match_native(cantilever_fmu, multisine_head, start, params, effects):
    twin, path = cantilever_fmu
    u, fs = multisine_head
    u = u[:600]
    native = twin.with_params(**params)
    if effects == "seed":
        native = type(twin)(twin.params, twin.effects, 3)
    elif effects:
        native = native.with_effects((set(twin.effects) | {"input_delay"}) - {"measurement_noise"})
    ref = native.simulate(u, fs)
    y = fmu_simulate(path, u, fs, start_values=start)
    assert relative_rms(y, ref) <= 1e-9
    assert relative_rms(twin.simulate(u, fs), ref) > 1e-4  # the change is visible


def test_cli_export_fmu(tmp_path, capsys):
    from benchmarks.cli import main

    out = tmp_path / "c.fmu"
    code = main(["export-fmu", "cantilever", "--effects", "none", "--set", "f1_hz=800", "--seed", "4",
                 "-o", str(out), "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["validation_problems"] == [] and summary["effects"] == [] and summary["seed"] == 4
    root, cfg = _md(out)
    assert float(_var(root, "f1_hz").find("Real").get("start")) == 800.0
    assert _var(root, "effect_measurement_noise").find("Boolean").get("start") == "false"
    assert cfg["config"]["params"]["f1_hz"] == 800.0
    for bad in (["export-fmu", "cantilever", "-o", str(tmp_path / "x.zip")],
                ["export-fmu", "cantilever", "--set", "f1_hz=1e9", "-o", str(out)]):
        assert main(bad) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "Traceback" not in err
