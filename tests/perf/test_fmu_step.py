"""Per-step cost of the exported FMUs in an FMI host: acoustic ≤ 100 µs, cantilever ≤ 50 µs per
communication step with both cores busy; identified-model FMUs alongside.

Two hosts, both in this process through FMPy (a child process would time the imports too):

- ``host``: the FMU's step as a simulation tool pays it, FMPy's ``FMU2Slave`` instantiated once, then per step
  ``setReal(u)``, ``doStep``, ``getReal(y)`` (ctypes -> the FMU's loader -> pythonfmu's C++ -> our slave ->
  the twin's per-sample core);
- ``fmpy``: ``twins.fmu.check.fmu_simulate`` (``fmpy.simulate_fmu``: instantiation and initialisation, FMPy's
  input interpolation and recording per step on top of the above).

Each benchmark times 3000 steps (``extra_info["per_step_s"]``: best round / 3000; ``cpu_per_step_s``: the
process's CPU time of the best round). The 1-minute load average is in ``extra_info["loadavg"]``: compare
figures only at similar load. ``acoustic_parallel_reference``: the acoustic per-sample path as it was
(numba's parallel kernel launched once per sample, the twin's array functions on one-sample arrays).
"""

import os
import time

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

STEPS = 3000
TARGETS = {"acoustic": 100e-6, "cantilever": 50e-6}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    from sysid.polynomial.narmax import NARXPoly
    from tests._polysys import narx_record
    from twins.acoustic import AcousticTwin
    from twins.cantilever import CantileverTwin
    from twins.fmu import export_fmu
    from twins.fmu.model_export import export_model_fmu

    d = tmp_path_factory.mktemp("fmu_step")
    m = NARXPoly().fit(narx_record(1500, seed=0, noise=0.01).replace(fs=1000.0))
    return {
        "acoustic": (export_fmu(AcousticTwin(), d / "acoustic.fmu"), 100e6),
        "cantilever": (export_fmu(CantileverTwin(), d / "cantilever.fmu"), 10e3),
        "narx-poly": (export_model_fmu(m, d / "narx.fmu"), 1000.0),
    }


class _Host:
    """FMPy's FMU2Slave, instantiated and initialised once; ``run(u)`` steps on from where it stopped."""

    def __init__(self, path, fs):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        self.folder = extract(str(path))
        md = read_model_description(self.folder)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        self.vu, self.vy, self.h, self.t = [vr["u"]], [vr["y"]], 1.0 / fs, 0.0
        self.fmu = FMU2Slave(
            guid=md.guid,
            unzipDirectory=self.folder,
            modelIdentifier=md.coSimulation.modelIdentifier,
            instanceName="bench",
        )
        self.fmu.instantiate()
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def run(self, u):
        fmu, vu, vy, h, t = self.fmu, self.vu, self.vy, self.h, self.t
        for v in u.tolist():
            fmu.setReal(vu, [v])
            fmu.doStep(t, h)
            fmu.getReal(vy)
            t += h
        self.t = t

    def close(self):
        import shutil

        self.fmu.terminate()
        self.fmu.freeInstance()
        shutil.rmtree(self.folder, ignore_errors=True)


def _parallel_reference(monkeypatch):
    """The acoustic per-sample path before: parallel kernel per sample, array amplifier and measure (the FMU
    runs in this process and uses its already imported ``twins``, so the switches reach it)."""
    import twins.acoustic.amplifier as amp
    from twins.acoustic import AcousticTwin

    monkeypatch.setattr(amp, "PARALLEL_MIN", 0)
    monkeypatch.setattr(AcousticTwin, "sample_amplifier", lambda self: None)
    monkeypatch.setattr(AcousticTwin, "sample_measure", None)


@pytest.mark.parametrize("mode", ["host", "fmpy"])
@pytest.mark.parametrize("name", ["acoustic", "acoustic_parallel_reference", "cantilever", "narx-poly"])
def test_fmu_step(benchmark, fmus, name, mode, monkeypatch):
    from twins.fmu.check import fmu_simulate

    if name == "acoustic_parallel_reference":
        _parallel_reference(monkeypatch)
        benchmark.extra_info["reference"] = f"test_fmu_step[{mode}-acoustic]"
    path, fs = fmus[name.split("_")[0]]
    u = np.sin(2 * np.pi * 0.001 * np.arange(STEPS))
    if mode == "host":
        host = _Host(path, fs)
        host.run(u[:10])  # numba compilation outside the timing
        call, args = host.run, (u,)
    else:
        fmu_simulate(path, u[:10], fs)  # imports and numba compilation outside the timing
        call, args = fmu_simulate, (path, u, fs)
    cpu = []

    def timed(*a):
        c0 = time.process_time()
        call(*a)
        cpu.append(time.process_time() - c0)

    benchmark.extra_info.update({"steps": STEPS, "items": STEPS, "host": mode, "loadavg": os.getloadavg()[0]})
    if name in TARGETS:
        benchmark.extra_info["target_s"] = TARGETS[name] * STEPS
    try:
        benchmark.pedantic(timed, args=args, rounds=3, iterations=1)
    finally:
        if mode == "host":
            host.close()
    benchmark.extra_info["cpu_per_step_s"] = min(cpu) / STEPS
    if benchmark.stats is not None:  # None with --benchmark-disable (the default outside make bench)
        benchmark.extra_info["per_step_s"] = benchmark.stats.stats.min / STEPS
