"""Per-step cost of the exported FMUs in an FMI host: acoustic ≤ 100 µs, cantilever ≤ 50 µs per
communication step with both cores busy; identified-model FMUs alongside.

One step = FMPy's co-simulation loop (setReal, doStep, getReal, recording) + pythonfmu's C->Python call + the
per-sample core. Each benchmark runs 3000 steps (``extra_info["per_step_s"]`` is the mean per step). The
machine's 1-minute load average is recorded in ``extra_info["loadavg"]``: compare figures only at similar load.
The acoustic per-sample path is serial (``twins.acoustic.amplifier.PARALLEL_MIN``): numba's
parallel kernel was launched once per sample (164 µs per step with both cores busy).
"""

import os

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

STEPS = 3000


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    from sysid.polynomial import NARXPoly
    from tests._polysys import narx_record
    from twins.acoustic import AcousticTwin
    from twins.cantilever import CantileverTwin
    from twins.fmu import export_fmu
    from twins.fmu.model_export import export_model_fmu

    d = tmp_path_factory.mktemp("fmu_step")
    m = NARXPoly().fit(narx_record(1500, seed=0, noise=0.01).replace(fs=1000.0))
    return {"acoustic": (export_fmu(AcousticTwin(), d / "acoustic.fmu"), 100e6, 100e-6),
            "cantilever": (export_fmu(CantileverTwin(), d / "cantilever.fmu"), 10e3, 50e-6),
            "narx-poly": (export_model_fmu(m, d / "narx.fmu"), 1000.0, None)}


@pytest.mark.parametrize("name", ["acoustic", "acoustic_parallel_reference", "cantilever", "narx-poly"])
def test_fmu_step(benchmark, fmus, name, monkeypatch):
    """``acoustic_parallel_reference``: the acoustic FMU with the per-sample parallel launch it had before
    (the FMU runs in this process and uses its already imported ``twins``, so the switch reaches it)."""
    from twins.fmu.check import fmu_simulate

    if name == "acoustic_parallel_reference":
        import twins.acoustic.amplifier as amp

        monkeypatch.setattr(amp, "PARALLEL_MIN", 0)
        benchmark.extra_info["reference"] = "test_fmu_step[acoustic]"
    path, fs, target = fmus[name.split("_")[0]]
    u = np.sin(2 * np.pi * 0.001 * np.arange(STEPS))
    fmu_simulate(path, u[:10], fs)  # imports and numba compilation outside the timing
    benchmark.extra_info.update({"steps": STEPS, "items": STEPS, "loadavg": os.getloadavg()[0]})
    if target and name != "acoustic_parallel_reference":
        benchmark.extra_info["target_s"] = target * STEPS
    benchmark.pedantic(fmu_simulate, args=(path, u, fs), rounds=3, iterations=1)
    if benchmark.stats is not None:  # None with --benchmark-disable (the default outside make bench)
        benchmark.extra_info["per_step_s"] = benchmark.stats.stats.min / STEPS
