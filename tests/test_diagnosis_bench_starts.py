"""Where a trial's fit starts, guarded by benchmark seeds (records made by the benchmark's own generator).

- Case 515: the tanks, a slow drift (ramp + cycle of period 1.3 records) on a steps record at 0.36 Hz, validated on
  noise. The calibration moved the initial level by 1.9 % to take up the drift (under the 2 % that made the given
  configuration a starting point); the drift's trial started with its period on the range's lower bound, where the
  least-squares steps were cut short (its amplitudes stayed at 10⁻⁵ of the drift); and the core refit beside the
  drift, 1 % better on the estimation record, took the validation SSE 250× above the held fit's. Verdict
  `unexplained`, nothing named.
"""

from __future__ import annotations

import pytest

from benchmarks.diagnosis_bench.cases import draw_case
from benchmarks.diagnosis_bench.truth import make_records
from twins.discrepancy.options import DiagnoseOptions
from twins.discrepancy.prediction import simulate, sse


@pytest.fixture(scope="module")
def case515():
    case = draw_case(515)
    assert case.model == "cascaded-tanks" and case.mechanism == "drift_slow" and case.est_kind == "steps"
    return make_records(case)


def test_a_fit_that_starts_on_a_bound_reaches_the_drift(case515):
    """The drift fitted with the core held at the truth from the pre-scan's start (period on its lower bound, the
    amplitudes 0) within the stage-A budget: its estimation SSE within 5 % of the true drift's (0.095 with the
    start kept on the bound, 0.0256 for the truth)."""
    from twins.discrepancy.diagnose import _prepare
    from twins.discrepancy.trials import make_stage, run_trial

    b = case515
    opts = DiagnoseOptions()
    inp = _prepare(b["twin"], b["est"], b["val"], opts)  # the ranges the diagnosis follows
    est, base = inp.est, inp.given
    p = b["params"]
    truth = base.with_effects({"slow_drift"}).with_params(
        drift_rate=p["rate"], drift_sin=p["sine"], drift_cos=p["cosine"], drift_period_s=p["period_s"]
    )
    sse_true = sse(est.output, simulate(truth, est), opts.skip)
    a_est = {**make_stage(base, est, inp.val, opts).analysis_est, "fs": est.fs}  # what guides the pre-scan
    tr = run_trial(base, "slow_drift", est, inp.val, list(inp.core), a_est, opts, refit_core=False)
    assert tr.sse_est <= 1.05 * sse_true
    assert sse(est.output, simulate(base, est), opts.skip) > 3 * sse_true  # the drift is there to be found


def test_a_drift_the_calibration_took_up_is_named(case515):
    """Diagnosed for one round, the slow drift leads and is stated (the truth: a ramp + slow cycle)."""
    from twins.discrepancy import diagnose

    b = case515
    out = diagnose(b["twin"], b["est"], b["val"], max_rounds=1, threads=1)
    assert out["verdict"] == "discrepancy"
    first = out["causes"][0]
    assert "slow_drift" in [first["effect"], *first.get("group", [])]
    assert first["confidence"] >= 0.5


@pytest.mark.parametrize(
    ("seed", "mechanism", "named"),
    [
        (142, "quantization", {"output_quantization"}),  # an overflow that never engages is not named beside it
        (58, "limiter", set()),  # a settling drift fitted to a calibration's error is not named
    ],
)
def test_a_trial_from_the_configuration_as_given_is_judged_against_it(seed, mechanism, named):
    """Cases 142 (a quantiser on the tanks, AR(1) noise of pole 0.93) and 58 (a limiter about the tanks' operating
    level): the calibration bent to the estimation record predicts the validation record 3.6× and 21× worse than the
    configuration as given. A trial started from that configuration (an overflow above every level reached) or a
    settling drift refitted with the core claimed the difference as its gain, at 0.98 and 0.97."""
    from twins.discrepancy import diagnose

    case = draw_case(seed)
    assert case.model == "cascaded-tanks" and case.mechanism == mechanism
    b = make_records(case)
    out = diagnose(b["twin"], b["est"], b["val"], max_rounds=3, threads=1)
    stated = {c["effect"] for c in out["causes"] if c["effect"] != "unexplained" and c["confidence"] >= 0.5}
    assert stated == named
