"""Speed of one acoustic diagnosis: a 2 ms record at 5 MHz (10 000 samples, estimation multisine and
validation chirp), compression injected as a tanh limiter of the drive on the bare twin's simulation with 1 %
noise, diagnosed from the default configuration (its Rapp compression re-tested) with the CLI's 3 rounds, in
under 3 minutes on 2 cores. The machine's load average is recorded beside the time (``extra_info``), since
the machine is shared. Run by ``make bench``."""

import os

import pytest
from discrepancy_outside import outside_case

from twins.acoustic import AcousticTwin
from twins.discrepancy import diagnose


@pytest.mark.slow
def test_diagnose_acoustic_2ms_at_5mhz(benchmark):
    start, est, val, _ = outside_case("tanh", 0, start_effects=None)
    AcousticTwin.from_options(seed=0).simulate(est.u[:100], est.fs)  # numba cache outside the timing
    benchmark.extra_info["target_s"] = 180.0
    benchmark.extra_info["items"] = len(est) + len(val)
    benchmark.extra_info["load_before"] = os.getloadavg()[0]
    out = benchmark.pedantic(diagnose, args=(start, est, val), kwargs={"max_rounds": 3}, rounds=1, iterations=1)
    benchmark.extra_info["load_after"] = os.getloadavg()[0]
    assert out["causes"] and out["causes"][0]["effect"] == "amplifier_compression", out["causes"]
    stats = getattr(benchmark, "stats", None)
    if stats is not None:
        assert stats.stats.median < 180.0
