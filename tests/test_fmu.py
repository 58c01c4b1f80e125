"""FMU export: build, validate, round trip against the native twins, tunable parameters.

The exporter is exercised on small twins defined in ``tests/_fmu_toy.py`` (a stepped toy and an
FFT-simulated echo channel like the acoustic twin) and on the project's cantilever and acoustic twins.
Inputs are short: fmpy costs tens of microseconds per communication step.
"""

import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
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
    assert real.get("unit") == "um/V"
    assert (float(real.get("min")), float(real.get("max")), float(real.get("start"))) == (0.0, 10.0, 3.0)
    assert _var(root, "order").find("Integer").get("max") == "3"
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


@pytest.mark.parametrize(
    "start,change",
    [
        ({"tau_s": 0.05}, dict(params={"tau_s": 0.05})),
        ({"order": 3, "weights": "0.2;-1.5"}, dict(params={"order": 3, "weights": [0.2, -1.5]})),
        ({"fluid": "oil"}, dict(params={"fluid": "oil"})),
        (
            {"effect_offset": True, "offset_um": -1.25, "effect_measurement_noise": False},
            dict(params={"offset_um": -1.25}, effects={"lag", "offset"}),
        ),
    ],
)
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
    """Errors raised in the slave reach the importer as failed FMI calls (in this process: see
    test_cantilever_process_exits_cleanly for the exit-time abort that used to follow)."""
    import fmpy

    twin, path = toy_fmu
    log = []

    def logger(component, instance, status, category, message):
        log.append(message.decode() if isinstance(message, bytes) else str(message))

    with pytest.raises(Exception, match="fmi2ExitInitializationMode failed"):
        fmpy.simulate_fmu(
            str(path),
            stop_time=0.01,
            output_interval=1e-3,
            start_values={"fluid": "honey"},
            logger=logger,
            debug_logging=True,
        )
    with pytest.raises(Exception, match="fmi2DoStep failed"):
        fmpy.simulate_fmu(str(path), stop_time=0.01, output_interval=1.5e-3, logger=logger, debug_logging=True)
    # the importer's log names the problem (the twin's ConfigError, the step that is not 1/fs)
    text = "\n".join(log)
    assert "honey" in text and "not a whole number of sampling periods" in text
    # a whole number of periods: the input is held over the step (n samples of the same u)
    res = fmpy.simulate_fmu(
        str(path),
        stop_time=0.02,
        output_interval=2e-3,
        output=["y"],
        start_values={"effect_measurement_noise": False},
        input=np.array([(0.0, 1.0), (1.0, 1.0)], dtype=[("time", float), ("u", float)]),
    )
    ref = twin.with_effects({"lag"}).simulate(np.ones(20), 1000.0)
    assert np.allclose(np.asarray(res["y"])[1:], ref[1::2], rtol=0, atol=1e-12)


def test_wrapper_state_release_finds_the_loaded_binary(toy_fmu):
    """The exit-abort fix (twins.fmu.slave.release_wrapper_state) reaches pythonfmu's exported
    finalizePythonInterpreter in the binary the importer loaded, and only that one (RTLD_NOLOAD)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    from twins.fmu.slave import release_wrapper_state

    _, path = toy_fmu
    folder = extract(str(path))
    resources = Path(folder) / "resources"
    if sys.platform != "linux":
        pytest.skip("the pythonfmu 0.7 exit problem and its fix are Linux-specific")
    assert release_wrapper_state(resources) is False  # binary not loaded yet: nothing to release
    md = read_model_description(folder)
    fmu = FMU2Slave(
        guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="a"
    )
    fmu.instantiate()  # the slave released the PyState already; a second release is a no-op
    try:
        assert release_wrapper_state(resources) is True
    finally:
        fmu.freeInstance()


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
        "print('used', sys.modules['twins'].__file__)\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    proc = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120
    )
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
    assert core["kind"] == "response" and core["accuracy"]["relative_rms"] < 1e-6
    fs = 100e6
    u = _burst(fs, 8000)  # past the first arrival (2000 samples) and the echo (6000)
    y = fmu_simulate(path, u, fs)
    ref = twin.simulate(u, fs)  # with its seeded noise
    quiet = twin.with_effects({"echo"}).simulate(u, fs)
    signal = np.sqrt(np.mean(quiet**2))
    assert relative_rms(y, ref) < 1e-6
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
    assert relative_rms(y, ref) < 1e-6
    assert relative_rms(twin.with_effects({"echo"}).simulate(u, fs), ref) > 0.5


@pytest.mark.parametrize("effects,head", [({"echo"}, False), ({"echo", "crosstalk"}, True)])
def test_response_core_equals_direct_convolution(effects, head):
    """The per-sample core (head FIR + block-FFT tail) is the linear convolution with h, without delay."""
    from twins.fmu.response import ResponseCore, impulse_response

    twin = EchoTwin(effects=effects)
    fs = 100e6
    h = impulse_response(twin, fs)
    core = ResponseCore(h, twin.amplifier, None, fs)
    assert core.arrival > 1900 if not head else core.arrival < 100  # 20 us flight time / crosstalk at once
    assert core.block >= (1024 if not head else 64)
    assert bool(core.head) == head  # the crosstalk path arrives at once and is kept in the head
    rng = np.random.default_rng(1)
    u = rng.standard_normal(5000)  # white input: every tap of h matters
    ref = np.convolve(twin.amplifier(u), h)[: len(u)]
    y = core.run(u)
    # white input: expected error sqrt(dropped energy fraction); x3 for the finite record
    assert relative_rms(y, ref) < 3 * np.sqrt(core.head_dropped) + 1e-12
    # reset restarts from rest
    core.reset()
    assert np.array_equal(core.run(u[:300]), y[:300])


# ------------------------------------------------------------------------------------- cantilever twin
# Exit-time abort (fixed): pythonfmu 0.7's wrapper released its global PyState twice at process exit
# (static destructor, then its library destructor) whenever it was still mapped at exit, which the numba
# and scipy libraries of the cantilever make the rule. See twins.fmu.slave.release_wrapper_state and
# the README section "fmu". The cantilever FMU now runs in this process; one child process checks the exit.
_EXIT_CHILD = """
import sys
import numpy as np, fmpy
from twins.fmu.check import fmu_simulate
path = sys.argv[1]
u = 50 * np.sin(2 * np.pi * 20 * np.arange(200) / 10e3)
y = fmu_simulate(path, u, 10e3)
refused = 0
for kw in (dict(start_values={"hysteresis": "honey"}, output_interval=1e-4), dict(output_interval=1.5e-4)):
    try:
        fmpy.simulate_fmu(path, stop_time=0.002, **kw)
    except Exception:
        refused += 1
assert refused == 2 and np.abs(y).max() > 1
"""


CANTILEVER_CASES = {
    "default": ({}, {}, None),
    "bw_f1": ({"bw_alpha": 0.45, "f1_hz": 900.0}, {"bw_alpha": 0.45, "f1_hz": 900.0}, None),
    "pi": ({"hysteresis": "prandtl-ishlinskii"}, {"hysteresis": "prandtl-ishlinskii"}, None),
    "delay_no_noise": (
        {"effect_input_delay": True, "effect_measurement_noise": False},
        {},
        "+input_delay-measurement_noise",
    ),
    "seed3": ({"seed": 3}, {}, "seed"),
}


@pytest.fixture(scope="module")
def cantilever_runs(tmp_path_factory):
    from twins.cantilever import CantileverTwin

    twin = CantileverTwin()  # default configuration, measurement noise on, seed 0
    folder = tmp_path_factory.mktemp("cant")
    path = export_fmu(twin, folder / "cantilever.fmu")
    rec = twin.generate("thesis-multisine")
    u, fs = rec.u[:1000], rec.fs
    runs = {name: fmu_simulate(path, u, fs, start_values=case[0]) for name, case in CANTILEVER_CASES.items()}
    return twin, path, u, fs, runs


def test_cantilever_process_exits_cleanly(cantilever_runs, tmp_path):
    """A process that ran the cantilever FMU in-process, error cases included, and then exits normally
    (no os._exit) must exit with status 0. Before the fix this child aborted at exit in 22 of 30 runs
    (glibc "corrupted double-linked list", status 134; tests/perf/fmu_exit_stress.py --mode project)."""
    _, path, *_ = cantilever_runs
    script = tmp_path / "exit_child.py"
    script.write_text(_EXIT_CHILD)
    proc = subprocess.run(
        [sys.executable, str(script), str(path)],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_cantilever_fmu_round_trip(cantilever_runs):
    twin, path, u, fs, runs = cantilever_runs
    assert validate_fmu(str(path)) == []
    assert fs == 10e3
    assert relative_rms(runs["default"], twin.simulate(u, fs)) <= 1e-9
    root, _ = _md(path)
    assert _var(root, "gain_um_per_v").find("Real").get("unit") == "um/V"
    assert _var(root, "hysteresis").find("String").get("start") == "bouc-wen"


@pytest.mark.parametrize("case", [k for k in CANTILEVER_CASES if k != "default"])
def test_cantilever_tunable_parameters_match_native(cantilever_runs, case):
    twin, _, u, fs, runs = cantilever_runs
    _, params, effects = CANTILEVER_CASES[case]
    native = twin.with_params(**params)
    if effects == "seed":
        native = type(twin)(twin.params, twin.effects, 3)
    elif effects:
        native = native.with_effects((set(twin.effects) | {"input_delay"}) - {"measurement_noise"})
    ref = native.simulate(u, fs)
    assert relative_rms(runs[case], ref) <= 1e-9
    assert relative_rms(twin.simulate(u, fs), ref) > 1e-4  # the change is visible


def test_cli_export_fmu(tmp_path, capsys):
    from benchmarks.cli import main

    out = tmp_path / "c.fmu"
    code = main(
        ["export-fmu", "cantilever", "--effects", "none", "--set", "f1_hz=800", "--seed", "4", "-o", str(out), "--json"]
    )
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["validation_problems"] == [] and summary["effects"] == [] and summary["seed"] == 4
    root, cfg = _md(out)
    assert float(_var(root, "f1_hz").find("Real").get("start")) == 800.0
    assert _var(root, "effect_measurement_noise").find("Boolean").get("start") == "false"
    assert cfg["config"]["params"]["f1_hz"] == 800.0
    for bad in (
        ["export-fmu", "cantilever", "-o", str(tmp_path / "x.zip")],
        ["export-fmu", "cantilever", "--set", "f1_hz=1e9", "-o", str(out)],
    ):
        assert main(bad) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "Traceback" not in err


# --------------------------------------------------------------------------------------- acoustic twin
@pytest.fixture(scope="module")
def acoustic_fmu(tmp_path_factory):
    from twins.acoustic import AcousticTwin

    twin = AcousticTwin()  # default configuration: noise, ADC, amplifier compression on; seed 0
    return twin, export_fmu(twin, tmp_path_factory.mktemp("ac") / "acoustic.fmu")


@pytest.fixture(scope="module")
def chirp_head(acoustic_fmu):
    twin, _ = acoustic_fmu
    rec = twin.generate("thesis-chirp-1ms", duration=8e-5)  # 8000 samples: past the 69 us flight time
    return rec.u, rec.fs


def test_acoustic_fmu_round_trip(acoustic_fmu, chirp_head):
    twin, path = acoustic_fmu
    assert validate_fmu(str(path)) == []
    root, cfg = _md(path)
    assert cfg["fs"] == 100e6 and cfg["core"]["kind"] == "response"
    assert cfg["core"]["accuracy"]["relative_rms"] < 1e-9  # measured at export on a chirp, noise-free
    assert _var(root, "fluid").find("String").get("start") == "water"
    assert _var(root, "distance_m").find("Real").get("unit") == "m"
    u, fs = chirp_head
    ref = twin.simulate(u, fs)  # noise, 8-bit ADC, compression: all as in piezotwin simulate
    assert np.sqrt(np.mean(ref[7000:] ** 2)) > 10 * twin.params.noise_v  # the arrival is in the window
    y = fmu_simulate(path, u, fs)
    assert relative_rms(y, ref) <= 1e-9


def test_acoustic_parameter_change_matches_native(acoustic_fmu, chirp_head):
    twin, path = acoustic_fmu
    u, fs = chirp_head
    native = twin.with_params(distance_m=0.09, fluid="seawater").with_effects(twin.effects | {"wall_echo"})
    ref = native.simulate(u, fs)
    y = fmu_simulate(path, u, fs, start_values={"distance_m": 0.09, "fluid": "seawater", "effect_wall_echo": True})
    assert relative_rms(y, ref) <= 1e-9
    assert relative_rms(twin.simulate(u, fs), ref) > 0.1


def test_real_start_values_are_exact_doubles(tmp_path):
    """A calibrated value must survive the XML: tools that apply the declared start values get the twin."""
    import fmpy

    twin = ToyTwin.from_options(set_=["gain=3.0000000000000004,tau_s=0.1"])  # 3 + 1 ulp: 17 digits
    path = export_fmu(twin, tmp_path / "t.fmu", fs=1000.0)
    root, _ = _md(path)
    assert float(_var(root, "gain").find("Real").get("start")) == twin.params.gain
    u = _toy_input(50)
    res = fmpy.simulate_fmu(
        str(path),
        stop_time=0.05,
        output_interval=1e-3,
        output=["y"],
        apply_default_start_values=True,
        input=np.array(list(zip(np.arange(51) * 1e-3, np.append(u, u[-1]))), dtype=[("time", float), ("u", float)]),
    )
    assert np.array_equal(res["y"][1:], twin.simulate(u, 1000.0))


# ------------------------------------------------------------------------- tunable parameters (mid-run)
def _fmu_run_with_change(path, u, fs, k, change):
    """Step the FMU through ``u`` with fmpy's FMU2Slave, setting ``change`` (name -> float) between
    communication steps ``k - 1`` and ``k``; returns the outputs aligned with ``simulate``."""
    import shutil

    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(path))
    refs = {v.name: v.valueReference for v in md.modelVariables}
    folder = extract(str(path))
    slave = FMU2Slave(
        guid=md.guid, unzipDirectory=folder, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="tune"
    )
    try:
        slave.instantiate()
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        h, y = 1.0 / fs, np.empty(len(u))
        for i, ui in enumerate(u):
            if i == k:
                slave.setReal([refs[n] for n in change], list(change.values()))
            slave.setReal([refs["u"]], [float(ui)])
            slave.doStep(currentCommunicationPoint=i * h, communicationStepSize=h)
            y[i] = slave.getReal([refs["y"]])[0]
        slave.terminate()
    finally:
        slave.freeInstance()
        shutil.rmtree(folder, ignore_errors=True)
    return y


def _native_with_change(twin, u, fs, k, change):
    stepper = twin.make_stepper(fs)
    y = np.empty(len(u))
    for i, ui in enumerate(u):
        if i == k:
            stepper.retune(twin.with_params(**change))
        y[i] = stepper.step(float(ui))
    return y


@pytest.mark.parametrize(
    "change",
    [
        {"gain_um_per_v": 0.4, "bw_beta": 0.03},  # hysteresis
        {"f1_hz": 900.0, "creep_per_decade": 0.03, "noise_um": 0.02, "offset_um": 1.5},  # modes, creep, sensor
    ],
)
def test_cantilever_tunable_change_mid_run_matches_native(cantilever_runs, change):
    """A tunable parameter set between communication steps acts from the next step on, with the state
    (hysteresis, modes, creep, sensor, noise generator) carried over: exactly as the native stepper's retune."""
    twin, path, u, fs, _ = cantilever_runs
    n, k = 400, 150
    u = u[:n]
    y = _fmu_run_with_change(path, u, fs, k, change)
    ref = _native_with_change(twin, u, fs, k, change)
    assert np.array_equal(y, ref)
    plain = twin.simulate(u, fs)
    assert np.array_equal(y[:k], plain[:k])  # nothing changes before the step
    assert relative_rms(y[k:], plain[k:]) > 1e-3  # the change is visible afterwards
    # carried state, not a restart: the same change made at t = 0 gives a different tail
    restarted = twin.with_params(**change).simulate(u, fs)
    assert relative_rms(y[k:], restarted[k:]) > 1e-3


def test_cantilever_variability_declared(cantilever_runs):
    from twins.cantilever import CantileverTwin

    _, path, *_ = cantilever_runs
    root, cfg = _md(path)
    assert validate_fmu(str(path)) == []
    tunable = {sv.get("name") for sv in root.iter("ScalarVariable") if sv.get("variability") == "tunable"}
    assert tunable == set(CantileverTwin.TUNABLE_PARAMS)
    assert {"gain_um_per_v", "f1_hz", "bw_alpha", "noise_um", "creep_per_decade"} <= tunable
    for name in (
        "input_delay_s",
        "max_substep_s",
        "initial_state_um",
        "creep_elements",
        "pi_operators",
        "hysteresis",
        "seed",
        "fs",
        "effect_creep",
        "effect_input_delay",
        "effect_measurement_noise",
    ):
        assert _var(root, name).get("variability") == "fixed", name


def test_acoustic_parameters_stay_fixed(acoustic_fmu):
    _, path = acoustic_fmu
    root, _ = _md(path)
    params = [sv for sv in root.iter("ScalarVariable") if sv.get("causality") == "parameter"]
    assert params and all(sv.get("variability") == "fixed" for sv in params)


def test_stepper_retune_refuses_layout_change():
    from sysid.errors import ConfigError
    from twins.cantilever import CantileverTwin

    twin = CantileverTwin()
    stepper = twin.make_stepper(10e3)
    stepper.step(1.0)
    for bad in ({"creep_elements": 3}, {"hysteresis": "prandtl-ishlinskii"}, {"max_substep_s": 1e-6}):
        with pytest.raises(ConfigError, match="state layout would change"):
            stepper.retune(twin.with_params(**bad))
    with pytest.raises(ConfigError, match="state layout would change"):
        stepper.retune(twin.with_effects(twin.effects | {"saturation"}))
    assert stepper.twin is twin  # refused: nothing replaced


def test_cantilever_invalid_tunable_value_fails_the_step(cantilever_runs):
    """An out-of-range value set mid-run is refused by the next doStep, with the twin's reason."""
    _, path, u, fs, _ = cantilever_runs
    with pytest.raises(Exception, match="fmi2DoStep failed"):
        _fmu_run_with_change(path, u[:20], fs, 10, {"f1_hz": 1e9})
