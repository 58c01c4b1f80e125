"""A hidden input delay, and nothing else, on records that do not start at rest: the delay is named alone.

The records are those of ``tests/perf/test_fmu_diagnose_long.py`` at a quarter of their length (0.5 s of
multisine, then twelve 0.125 s voltage steps at 10 kHz: 12 000 estimation and 8 000 validation samples): the
shipped cantilever (its noise on) driven by the input delayed by 0.37 ms, the first input held before the first
sample, plus 1 % white noise; the validation record is the tail of the same run (it starts mid-hold at −30 V).
The start twin is the cantilever kernel as a user's model (``fmu_diagnose_cases.kernel_class``, the FMU's samples
bit for bit) with the generic 10 nm quantiser.

Neither record starts as the twin assumes (at rest, the delay line zero-filled): the first ~20 ms of each carry
most of the residual, the twin's ring-down at f1 (1/(2π·701 Hz·0.021) ≈ 11 ms). A gain drift refitted with the
core mimics that start (g 0.33, τ 10.7 ms, the core gain lowered to match: only the first ~30 ms change), which
frees the core from it: named second (p 5e-5, confidence 0.78). On the full-length records this path opened only
when every trial better on the estimation record by a rounding-level amount was refitted with the core (fixed in
``candidates._refine``); on these shorter ones the held-core gain drift is round 2's validation leader by 0.05 %
(SSE 1758.7 against 1759.5), so it is refitted as the leader and the mimic remains: a known limitation, kept here
as a strict xfail (slow: 45 s CPU) until the start-up transient is handled by the method.
"""

import numpy as np
import pytest
from fmu_diagnose_cases import CORE, kernel_class

from sysid.data.record import Record
from twins.cantilever import CantileverTwin
from twins.cantilever.protocols import thesis_multisine
from twins.discrepancy import diagnose

FS = 10e3
DELAY_S = 3.7e-4
SCALE = 0.25  # of the long test's 80 000 samples


def _records() -> tuple[Record, Record]:
    multisine, _, _ = thesis_multisine({"fs": FS, "duration_s": 2.0 * SCALE, "signal_seed": 4})
    levels = [0.0, 60.0, 0.0, -60.0, 30.0, -30.0, 80.0, 0.0, -80.0, 0.0, 40.0, 0.0]
    u = np.concatenate([multisine, np.repeat(levels, int(5000 * SCALE))])
    k = np.arange(len(u), dtype=float)
    delayed = np.interp(k - DELAY_S * FS, k, u, left=u[0])
    y = CantileverTwin(seed=5).simulate(delayed, FS)
    y = y + 0.01 * np.std(y) * np.random.default_rng(9).standard_normal(len(u))
    n = int(0.6 * len(u))
    units = {"u": "V", "y": "um"}
    return (
        Record(u=u[:n], y=y[:n], fs=FS, units=units, source="delay-est"),
        Record(u=u[n:], y=y[n:], fs=FS, units=units, source="delay-val"),
    )


@pytest.fixture(scope="module")
def outcome():
    est, val = _records()
    twin = kernel_class(False).from_options(effect=["output_quantization:step=0.01"])
    return diagnose(twin, est, val, max_rounds=2, calibration_params=list(CORE))


def test_records_are_as_described():
    est, val = _records()
    assert (len(est), len(val)) == (12_000, 8_000)
    assert est.u[0] > 30.0 and np.all(val.u[:500] == val.u[0]) and val.u[0] == -30.0


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="a gain drift refitted with the core mimics the records' start-up transient")
def test_hidden_delay_named_alone(outcome):
    causes = outcome["causes"]
    assert [c["effect"] for c in causes] == ["input_delay"], [(c["effect"], c["confidence"]) for c in causes]
    assert abs(causes[0]["params"]["generic_input_delay_s"] - DELAY_S) <= 0.05 * DELAY_S
    # no second confident cause among round 2's candidates either
    second = [r for r in outcome["rounds"] if r.get("round") == 2 and "candidates" in r]
    assert all(not c["significant"] for r in second for c in r["candidates"])
