"""The real cases of the missing-physics diagnosis (``benchmarks/real_cases.py``, docs/diagnosis.md "Real cases"):
the example models a user writes first, diagnosed with the defaults on the benchmarks' measured records and scored
on their test records.

Default suite: the Bouc–Wen benchmark's multisine test is one period in steady state — the benchmark's own
model scores it to 3·10⁻⁷ m only from the periodic steady state, 4.6·10⁻⁵ m from rest. ``slow``: each case
diagnosed (cascaded tanks about 35 s of CPU, Bouc–Wen 80 s, Silverbox several minutes).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from benchmarks.datasets import load_dataset
from benchmarks.real_cases import CASES, EXAMPLES, run_case, score_tests
from twins.external import load_model

#: the benchmark's Bouc–Wen system (Noël & Schoukens 2016): m, c, k, and α/m, βγ, βδ in the catalog's form
BW_TRUE = {
    "m": 2.0,
    "c": 10.0,
    "k": 5e4,
    "bouc_wen_y_kappa": 5e4 / 2.0,
    "bouc_wen_y_b1": 1e3 * 0.8,
    "bouc_wen_y_b2": 1e3 * -1.1,
}


def test_bouc_wen_multisine_test_is_a_steady_state_period():
    cls = load_model(str(EXAMPLES / CASES["bouc-wen"].model))
    twin = cls()
    p = dataclasses.replace(twin.model_params(), **BW_TRUE, ode_substeps=8)
    rec = load_dataset("bouc-wen").tests["multisine"]
    u, y = np.asarray(rec.u, float), np.asarray(rec.y, float)
    rms = [
        float(np.sqrt(np.mean((cls.SPEC.run(u, rec.fs, p, {"bouc_wen@y"}, x0=x0)[0] - y) ** 2)))
        for x0 in (None, "periodic")
    ]
    assert rms[0] > 2e-5 and rms[1] < 5e-7, rms


@pytest.mark.slow
def test_cascaded_tanks_bounds_named_and_official_test_within_0_30_v():
    """The Torricelli model with no overflow written → the upper tank's bound named by the diagnosis (with the
    lower tank's), official test ≤ 0.30 V (0.685 V as given); with a black-box remainder fitted on the estimation
    record beside it, ≤ 0.27 V (0.259 V measured; the published grey-box record is 0.191 V)."""
    res = run_case("cascaded-tanks", progress=False, hybrid=True)
    assert {"overflow@x1", "overflow@x2"} <= set(res["named"]), res
    assert res["test_rmse_after"]["test-official"] <= 0.30 < 0.6 < res["test_rmse_before"]["test-official"], res
    assert res["test_rmse_hybrid"]["test-official"] <= 0.27, res


@pytest.mark.slow
def test_bouc_wen_hysteresis_named_and_multisine_within_goal():
    res = run_case("bouc-wen", progress=False)
    assert res["named"][:1] == ["bouc_wen@y"], res
    assert res["test_rmse_after"]["multisine"] <= 2e-6 < res["test_rmse_before"]["multisine"], res


@pytest.mark.slow
def test_silverbox_restoring_force_named_and_within_1_mv():
    res = run_case("silverbox", progress=False)
    assert any(e.endswith("_spring@x") for e in res["named"]), res
    assert res["test_rmse_after"]["multisine"] <= 1e-3, res


def test_score_tests_scores_from_the_initialisation_window():
    """The scorer skips each test's own window (cascaded tanks ``test-official``: 50 samples)."""
    data = load_dataset("cascaded-tanks")
    twin = load_model(str(EXAMPLES / CASES["cascaded-tanks"].model))()
    s = score_tests(twin, CASES["cascaded-tanks"], data)
    y = twin.simulate(np.asarray(data.tests["test"].u, float), data.fs)
    e = np.asarray(data.tests["test"].y, float) - y
    assert s["test"] == pytest.approx(float(np.sqrt(np.mean(e[4:] ** 2))))
    assert s["test-official"] == pytest.approx(float(np.sqrt(np.mean(e[50:] ** 2))))
