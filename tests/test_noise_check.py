"""The verdict's noise level against closed forms, and the benchmark's measurement of it
(:mod:`benchmarks.diagnosis_bench.noise_check`)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from benchmarks.diagnosis_bench.noise_check import perfect_excess, summarise
from twins.discrepancy.unexplained import EXCESS_LIMIT, noise_level

N = 1 << 16


def test_white_noise_is_measured_at_its_variance():
    rng = np.random.default_rng(1)
    y = 0.01 * rng.standard_normal(N)
    nl = noise_level(np.zeros(N), y, 1000.0)
    assert nl["sigma2"] == pytest.approx(1e-4, rel=0.05)


@pytest.mark.parametrize("rho", [0.6, 0.86])
def test_ar1_noise_is_seen_at_its_floor_the_limitation_the_benchmark_measures(rho):
    # the white-noise estimators see AR(1) noise at its high-frequency floor: var·(1 − ρ)/(1 + ρ)
    rng = np.random.default_rng(2)
    y = signal.lfilter([1.0], [1.0, -rho], rng.standard_normal(N))
    nl = noise_level(np.zeros(N), y, 1000.0)
    assert nl["sigma2"] / np.var(y) == pytest.approx((1 - rho) / (1 + rho), rel=0.1)


def test_summary_counts_per_colour_and_leaves_quantised_cases_out():
    rows = [
        {"mechanism": None, "noise_ar": 0.0, "excess": 1.0},
        {"mechanism": "limiter", "noise_ar": 0.0, "excess": 0.5},
        {"mechanism": None, "noise_ar": 0.9, "excess": 12.0},
        {"mechanism": None, "noise_ar": 0.88, "excess": 4.0},
        {"mechanism": "quantization", "noise_ar": 0.9, "excess": 1e30},
    ]
    t = {r["noise"]: r for r in summarise(rows, EXCESS_LIMIT)}
    assert t["white"]["cases"] == 2 and t["white"]["above_limit"] == 0
    assert t["AR(1) 0.85–0.95"] == {
        "noise": "AR(1) 0.85–0.95",
        "cases": 2,
        "median": 8.0,
        "max": 12.0,
        "above_limit": 1,
    }
    assert "AR(1) 0.50–0.70" not in t


def test_a_white_noise_case_of_the_generator_scores_near_one():
    r = perfect_excess(23)  # piezo-stage, nothing hidden, white noise
    assert r["mechanism"] is None and r["noise_ar"] == 0.0
    assert 0.2 < r["excess"] < 3.0
