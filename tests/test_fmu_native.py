"""The per-sample calls an FMU's loader answers in C (:mod:`twins.fmu.shim`, :mod:`twins.fmu.native`) and the
compiled stepping loop with its memory of earlier runs (:class:`twins.external.fmu.FMUCore`): the outputs are
those of the twin, bit for bit, whichever path a step takes (C or the slave's Python), across parameter changes,
step-size changes, a reset and a refused input."""

from __future__ import annotations

import shutil
import sys

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from sysid.errors import DataError  # noqa: E402
from twins.cantilever import CantileverTwin  # noqa: E402
from twins.external.fmu import FMUCore  # noqa: E402
from twins.fmu import export_fmu  # noqa: E402
from twins.fmu.native import Block  # noqa: E402

pytestmark = pytest.mark.skipif(sys.platform != "linux" or shutil.which("gcc") is None, reason="loader needs gcc")

FS = 10e3


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    return export_fmu(CantileverTwin(), tmp_path_factory.mktemp("native") / "cantilever.fmu")


def _u(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return 40 * np.sin(2 * np.pi * 60 * np.arange(n) / FS) + 5 * rng.standard_normal(n)


class _Host:
    def __init__(self, path, quiet: bool):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        self.folder = extract(str(path))
        md = read_model_description(self.folder)
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(
            guid=md.guid, unzipDirectory=self.folder, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="n"
        )
        self.fmu.instantiate()
        self.quiet = quiet
        self.start()

    def start(self):
        if self.quiet:
            self.fmu.setBoolean([self.vr["effect_measurement_noise"]], [False])
        self.fmu.setupExperiment(startTime=0.0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.t = 0.0

    @property
    def block(self) -> Block:
        return Block.from_address(self.fmu.component)

    def steps(self, u, h=1 / FS, change_at=None, change=None):
        y = np.empty(len(u))
        for i, v in enumerate(u):
            if i == change_at:
                self.fmu.setReal([self.vr[k] for k in change], list(change.values()))
            self.fmu.setReal([self.vr["u"]], [float(v)])
            self.fmu.doStep(self.t, h)
            y[i] = self.fmu.getReal([self.vr["y"]])[0]
            self.t += h
        return y

    def close(self):
        self.fmu.freeInstance()
        shutil.rmtree(self.folder, ignore_errors=True)


def _quiet_twin():
    return CantileverTwin().with_effects(CantileverTwin().effects - {"measurement_noise"})


def test_quiet_steps_run_in_c_and_equal_the_twin(fmu):
    host = _Host(fmu, quiet=True)
    try:
        u = _u(1500)
        y = host.steps(u)
        assert host.block.attached == 1 and host.block.stepped_here == 1  # the last steps ran in the loader
        assert y.tobytes() == _quiet_twin().simulate(u, FS).tobytes()
        assert host.fmu.getRealStatus(2) == pytest.approx(1500 / FS)  # fmi2LastSuccessfulTime
    finally:
        host.close()


def test_noise_on_steps_in_python_and_equals_the_twin(fmu):
    host = _Host(fmu, quiet=False)
    try:
        u = _u(600)
        y = host.steps(u)
        assert host.block.attached == 1 and host.block.stepped_here == 0  # the noise is drawn in Python
        assert y.tobytes() == CantileverTwin().simulate(u, FS).tobytes()
    finally:
        host.close()


def test_change_mid_run_matches_the_native_retune(fmu):
    """A tunable change disarms the step in C; the slave's Python step retunes and arms it again."""
    change = {"gain_um_per_v": 0.4, "f1_hz": 900.0}
    twin = _quiet_twin()
    u, k = _u(500, 1), 200
    host = _Host(fmu, quiet=True)
    try:
        y = host.steps(u, change_at=k, change=change)
        assert host.block.stepped_here == 1
    finally:
        host.close()
    stepper = twin.make_stepper(FS)
    ref = np.empty(len(u))
    for i, v in enumerate(u):
        if i == k:
            stepper.retune(twin.with_params(**change))
        ref[i] = stepper.step(float(v))
    assert y.tobytes() == ref.tobytes()


def test_step_size_change_and_back(fmu):
    """Steps of 2/fs (the input held over both samples) go to the slave's Python step; 1/fs runs in C again."""
    u = _u(300, 2)
    host = _Host(fmu, quiet=True)
    try:
        y = np.concatenate([host.steps(u[:100]), host.steps(u[100:150], h=2 / FS), host.steps(u[150:])])
        assert host.block.stepped_here == 1
    finally:
        host.close()
    stepper = _quiet_twin().make_stepper(FS)
    ref = np.empty(len(u))
    for i, v in enumerate(u):
        for _ in range(2 if 100 <= i < 150 else 1):
            ref[i] = stepper.step(float(v))
    assert y.tobytes() == ref.tobytes()


def test_non_finite_input_fails_the_step_and_reset_restarts(fmu):
    from fmpy.fmi1 import FMICallException

    u = _u(300, 3)
    host = _Host(fmu, quiet=True)
    try:
        first = host.steps(u)
        with pytest.raises(FMICallException):
            host.steps([np.nan])
        host.fmu.reset()
        host.start()
        assert host.steps(u).tobytes() == first.tobytes()
        # several values in one call: u in the loader, a parameter through the slave
        host.fmu.setReal([host.vr["u"], host.vr["offset_um"]], [1.5, 0.25])
        got = host.fmu.getReal([host.vr["u"], host.vr["offset_um"], host.vr["y"]])
        assert got[:2] == [1.5, 0.25] and got[2] == first[-1]
    finally:
        host.close()


def test_core_remembers_runs_and_returns_copies(fmu):
    core = FMUCore(fmu)
    params_cls, _ = core.params_class(["gain_um_per_v"])
    p = params_cls(effect_measurement_noise=False)
    u = _u(800, 4)
    y1 = core(u, FS, p, frozenset())
    assert (core.results.hits, core.results.misses) == (0, 1)
    assert y1.tobytes() == _quiet_twin().simulate(u, FS).tobytes()
    y1[:] = 0.0  # the caller's copy
    y2 = core(u.copy(), FS, p, frozenset())
    assert core.results.hits == 1 and y2.tobytes() == _quiet_twin().simulate(u, FS).tobytes()
    y3 = core(u, FS, params_cls(effect_measurement_noise=False, gain_um_per_v=0.4), frozenset())
    assert core.results.misses == 2 and not np.array_equal(y3, y2)
    core.results.items.clear()
    core.results.limit = 0  # no memory: every run simulated
    core(u, FS, p, frozenset())
    core(u, FS, p, frozenset())
    assert core.results.misses == 4 and not core.results.items


def test_core_failed_run_in_c_raises_and_recovers(fmu):
    core = FMUCore(fmu)
    params_cls, _ = core.params_class(["gain_um_per_v"])
    p = params_cls(effect_measurement_noise=False)
    u = np.ones(50)
    u[30] = np.nan  # reaches the slave after 30 steps in C: the slave refuses it
    with pytest.raises(DataError, match="simulation failed.*sample 30"):
        core(u, FS, p, frozenset())
    y = core(np.ones(50), FS, p, frozenset())
    assert y.tobytes() == _quiet_twin().simulate(np.ones(50), FS).tobytes()
