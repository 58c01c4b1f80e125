"""Speed of the exported FMUs: cost per communication step and per simulated second.

Run by ``make bench``. One fmpy co-simulation step = fmpy's own loop (input interpolation, setReal,
doStep, getReal, recording) + pythonfmu's C->Python call + the twin's per-sample core; the cores are also
timed alone. The FMUs are built once per session in a temporary folder. The FMUs run in this process (a
child process would time the imports too). The former abort at exit is fixed in the slave (README, fmu).
"""

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")


@pytest.fixture(scope="module")
def cantilever(tmp_path_factory):
    from twins.cantilever import CantileverTwin
    from twins.fmu import export_fmu

    twin = CantileverTwin()
    return twin, export_fmu(twin, tmp_path_factory.mktemp("perf") / "cantilever.fmu")


@pytest.fixture(scope="module")
def acoustic(tmp_path_factory):
    acoustic_mod = pytest.importorskip("twins.acoustic")
    from twins.fmu import export_fmu

    twin = acoustic_mod.AcousticTwin()
    return twin, export_fmu(twin, tmp_path_factory.mktemp("perf") / "acoustic.fmu")


def test_cantilever_fmu_1000_steps(benchmark, cantilever):
    from twins.fmu.check import fmu_simulate

    _, path = cantilever
    fs = 10e3
    u = 50 * np.sin(2 * np.pi * 20 * np.arange(1000) / fs)
    fmu_simulate(path, u[:10], fs)  # numba compile and module import outside the timing
    benchmark.extra_info["steps"] = len(u)
    benchmark.pedantic(fmu_simulate, args=(path, u, fs), rounds=3, iterations=1)


def test_cantilever_stepper_1000_samples(benchmark, cantilever):
    twin, _ = cantilever
    st = twin.make_stepper(10e3)
    u = (50 * np.sin(2 * np.pi * 20 * np.arange(1000) / 10e3)).tolist()

    def run():
        st.reset()
        for v in u:
            st.step(v)

    benchmark(run)


def test_acoustic_fmu_10000_steps(benchmark, acoustic):
    from twins.fmu.check import fmu_simulate

    _, path = acoustic
    fs = 100e6
    u = np.sin(2 * np.pi * 1e6 * np.arange(10000) / fs)
    fmu_simulate(path, u[:10], fs)
    benchmark.extra_info["steps"] = len(u)
    benchmark.pedantic(fmu_simulate, args=(path, u, fs), rounds=3, iterations=1)


def test_acoustic_response_core_10000_samples(benchmark, acoustic):
    from twins.fmu.cores import build_core, choose_core

    twin, _ = acoustic
    core = build_core(twin, 100e6, choose_core(twin, 100e6))
    u = np.sin(2 * np.pi * 1e6 * np.arange(10000) / 100e6).tolist()

    def run():
        core.reset()
        for v in u:
            core.step(v)

    benchmark(run)
