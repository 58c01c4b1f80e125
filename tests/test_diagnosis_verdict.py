"""The verdict once the causes are calibrated (:func:`twins.discrepancy.confidence.attributed_verdict`): a
discrepancy is attributed only where a catalog cause states at least ½; where the catalog fits the data with
causes that all state less — a mimic explaining a mechanism outside the catalog to the noise — the verdict is
``unexplained`` with the causes listed as candidates, and nothing is fitted to a residual already at the noise.

The rule, then case 208 of the diagnosis benchmark (docs/diagnosis-benchmark.md): a backlash between the drive and
the user's oscillator (outside its catalog) fitted as a sensor low-pass that explains the validation record to the
noise, stated at 0.40; the verdict was ``discrepancy``.
"""

from __future__ import annotations

import pytest

from benchmarks.diagnosis_bench.cases import draw_case
from benchmarks.diagnosis_bench.run import MAX_ROUNDS
from benchmarks.diagnosis_bench.truth import make_records
from twins.discrepancy import diagnose
from twins.discrepancy.confidence import CONFIDENT, attributed_verdict


def _c(effect: str, confidence: float) -> dict:
    return {"effect": effect, "confidence": confidence}


@pytest.mark.parametrize(
    "verdict, causes, expected",
    [
        ("discrepancy", [_c("creep", CONFIDENT)], "discrepancy"),
        ("discrepancy", [_c("slow_drift", 0.3), _c("creep", 0.7)], "discrepancy"),
        ("discrepancy", [_c("creep", 0.49), _c("slow_drift", 0.3)], "unexplained"),
        ("discrepancy", [_c("unexplained", 0.9)], "unexplained"),  # generic structure is not a named cause
        ("unexplained", [_c("creep", 0.9)], "unexplained"),  # above the noise stays so
        ("none", [], "none"),
    ],
)
def test_a_discrepancy_is_attributed_only_to_a_confident_cause(verdict, causes, expected):
    assert attributed_verdict(verdict, causes) == expected


@pytest.mark.heavy
def test_a_mimic_that_explains_an_outside_mechanism_leaves_the_verdict_unexplained():
    case = draw_case(208)
    assert (case.family, case.mechanism) == ("user", "backlash")
    b = make_records(case)
    out = diagnose(b["twin"], b["est"], b["val"], max_rounds=MAX_ROUNDS, threads=1)
    named = [c for c in out["causes"] if c["effect"] != "unexplained"]
    assert named, out["causes"]  # the mimic stays listed as a candidate
    assert max(c["confidence"] for c in named) < CONFIDENT
    assert not out["residual_vs_noise"]["outside"]  # it explains the record to the noise...
    assert out["verdict"] == "unexplained"  # ...but is not stated as the cause
    assert out.get("hybrid") is None


@pytest.mark.heavy
def test_the_cli_says_why_a_fitted_discrepancy_is_unexplained(tmp_path):
    import subprocess
    import sys

    from sysid.data.io import write_record

    b = make_records(draw_case(208))
    write_record(b["est"], tmp_path / "est.npz")
    write_record(b["val"], tmp_path / "val.npz")
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks.cli", "diagnose", "--model", "benchmarks/examples/piezo_stage.py"]
        + ["--data", str(tmp_path / "est.npz"), "--val", str(tmp_path / "val.npz"), "--max-rounds", str(MAX_ROUNDS)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0].endswith("verdict unexplained"), r.stdout
    assert "no cause stated" in r.stdout and "outside the model class" not in r.stdout, r.stdout
