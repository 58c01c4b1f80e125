"""A named cause whose parameters do not carry over from the estimation record to the validation record
(:mod:`twins.discrepancy.transfer`): marked, and its confidence capped at ``TRANSFER_CAP`` (< ½).

Cases of the diagnosis benchmark (docs/diagnosis-benchmark.md) on the piezo stage (a linear resonator, the user's
model): 412, a backlash on the drive (outside its catalog) fitted as an output echo (stated 0.96, verdict
``discrepancy``; its refit on the validation record moved the echo's delay by 15 % and removed 17 % of the
validation residual power), now fitted as a drive low-pass whose parameters do not carry over either. Right names
keep their confidence: case 102's echo and case 182's delay on the cantilever (their refits move them by under 1 %
and remove under 0.3 %), and case 166, a first-order lag of the drive: outside the user catalog when it was fitted
as a delay that did not carry over (0.93 capped), inside it since the generic drive low-pass (the lag group), and
named as that group's delay at 0.99 since a trial's start on a bound moves inside its range.
"""

from __future__ import annotations

import pytest

from benchmarks.diagnosis_bench.cases import draw_case
from benchmarks.diagnosis_bench.run import MAX_ROUNDS
from benchmarks.diagnosis_bench.truth import make_records
from twins.discrepancy import diagnose
from twins.discrepancy.confidence import CONFIDENT, TRANSFER_CAP
from twins.discrepancy.transfer import MIN_DROP, MIN_MOVE


def _run(seed: int) -> dict:
    b = make_records(draw_case(seed))
    return diagnose(b["twin"], b["est"], b["val"], max_rounds=MAX_ROUNDS, threads=1)


@pytest.mark.heavy
def test_a_mimic_whose_parameters_do_not_carry_over_is_not_stated():
    assert draw_case(412).mechanism == "backlash"
    out = _run(412)
    cause = next(c for c in out["causes"] if c["effect"] != "unexplained")  # the leading mimic, whichever it is
    mark = cause["untransferable"]
    assert mark["drop"] >= MIN_DROP and mark["p_value"] < 0.01
    assert max(abs(b - a) / abs(a) for a, b in mark["params"].values()) >= MIN_MOVE
    assert cause["confidence"] <= TRANSFER_CAP and "do not carry over" in cause["evidence"]
    assert out["verdict"] == "unexplained"  # an outside mechanism: no cause stated


@pytest.mark.heavy
@pytest.mark.parametrize(
    "seed, mechanism, effect",
    [(102, "echo", "output_echo"), (182, "delay", "input_delay"), (166, "input_lag", "input_delay")],
)
def test_a_right_cause_carries_over(seed, mechanism, effect):
    assert draw_case(seed).mechanism == mechanism
    out = _run(seed)
    cause = next(c for c in out["causes"] if c["effect"] == effect)
    assert "untransferable" not in cause and cause["confidence"] >= CONFIDENT
    assert out["verdict"] == "discrepancy"
