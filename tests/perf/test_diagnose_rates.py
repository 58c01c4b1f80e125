"""Speed of the acoustic diagnosis on the records users have, from the bare twin: drive compression hidden as a
tanh limiter, a cubic soft clip and a hard clip (10–20 % at the peak, one limiter for both records, 1 % output
noise), estimation a 900–1350 kHz multisine and validation a chirp of the same length and peak, diagnosed from
the bare configuration (``--effects none``) with the CLI's 3 rounds.

Targets: 10 000 samples at 5 MHz and at 25 MHz ≤ 3 CPU-minutes each, 27 000 samples at 6.75 MHz (the
dissertation's preprocessed size) ≤ 6 CPU-minutes, the right cause named in each. The machine is shared: the
process CPU time is asserted, the load average before and after is recorded (``extra_info``). Run by
``make bench``.
"""

import os
import time

import numpy as np
import pytest
from discrepancy_outside import _limiter

from sysid.data.record import Record
from sysid.signals.excitation import chirp, multisine
from twins.acoustic import AcousticTwin
from twins.discrepancy import diagnose

pytestmark = pytest.mark.perf

CASES = [(5e6, 10_000, 180.0), (25e6, 10_000, 180.0), (6.75e6, 27_000, 360.0)]


def _records(kind: str, fs: float, n: int, compression: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    T = n / fs
    ue = np.asarray(multisine(fs=fs, duration=T, band=(900e3, 1350e3), amplitude=0.4, seed=seed))[:n]
    uv = np.asarray(chirp(fs=fs, duration=T, f0=900e3, f1=1350e3, amplitude=0.4))[:n]
    lim = _limiter(kind, 0.4, compression)
    bare = AcousticTwin.from_options(effects="none", seed=seed)
    out = []
    for u in (ue, uv):
        y = bare.simulate(lim(u), fs)
        y = y + 0.01 * np.sqrt(np.mean(y**2)) * rng.standard_normal(n)
        out.append(Record(u=u, y=y, fs=fs))
    return out


@pytest.mark.parametrize("kind", ["tanh", "cubic", "clip"])
@pytest.mark.parametrize(("fs", "n", "target"), CASES, ids=[f"{n}_at_{fs / 1e6:g}MHz" for fs, n, _ in CASES])
def test_diagnose_acoustic_from_the_bare_twin(benchmark, kind, fs, n, target):
    est, val = _records(kind, fs, n, 0.15)
    start = AcousticTwin.from_options(effects="none", seed=0)
    start.simulate(est.u[:100], fs)  # numba's cache outside the timing
    benchmark.extra_info.update(
        target_s=target, items=2 * n, fs_hz=fs, samples=n, kind=kind, load_before=os.getloadavg()[0]
    )
    c0 = time.process_time()
    out = benchmark.pedantic(diagnose, args=(start, est, val), kwargs={"max_rounds": 3}, rounds=1, iterations=1)
    cpu = time.process_time() - c0
    benchmark.extra_info.update(cpu_s=cpu, load_after=os.getloadavg()[0])
    assert out["causes"] and out["causes"][0]["effect"] == "amplifier_compression", out["causes"]
    assert cpu < target
