"""The significance test of the diagnosis counts each effect's degrees of freedom.

Closed form: nested least-squares models on pure noise. Under the null hypothesis (the k extra regressors
explain nothing) ``F = (N − k_total)/k · (SSE₀ − SSE₁)/SSE₁`` follows F(k, N − k_total), so the p-values of
:func:`twins.discrepancy.prediction.significance` are uniform — whatever k, so a richer family (larger k, a
larger gain by flexibility alone) is not found significant more often than a poorer one. Counting only the
extra parameters in the denominator (N − k instead of N − k_total) makes the in-sample test anti-conservative
when the model fits many parameters, which the last test shows. (The diagnosis scores validation residuals, to
which no parameter was fitted, and so passes k alone: see :mod:`twins.discrepancy.ranking`.)
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from twins.discrepancy.prediction import significance


def _p_values(n: int, m: int, k: int, reps: int, seed: int, total: bool = True) -> np.ndarray:
    """p-values of adding k random regressors to m on pure Gaussian noise (N = n samples)."""
    rng = np.random.default_rng(seed)
    out = np.empty(reps)
    for r in range(reps):
        y = rng.standard_normal(n)
        x0 = rng.standard_normal((n, m))
        x1 = np.hstack([x0, rng.standard_normal((n, k))])
        sse0 = float(np.sum((y - x0 @ np.linalg.lstsq(x0, y, rcond=None)[0]) ** 2))
        sse1 = float(np.sum((y - x1 @ np.linalg.lstsq(x1, y, rcond=None)[0]) ** 2))
        out[r] = significance(sse0, sse1, n, k, m + k) if total else significance(sse0, sse1, n, k)
    return out


def test_pure_noise_p_values_uniform_for_any_k():
    for k in (1, 3, 6):
        p = _p_values(200, 4, k, 400, seed=k)
        assert stats.kstest(p, "uniform").pvalue > 1e-3, k
        # the level the diagnosis uses (alpha / n_candidates ≈ 1e-3) is exceeded about as often as it should be
        assert 0.02 <= float(np.mean(p < 0.05)) <= 0.09, (k, float(np.mean(p < 0.05)))


def test_richer_family_gains_more_but_is_not_more_often_significant():
    rng = np.random.default_rng(5)
    n = 300
    gain = {}
    rate = {}
    for k in (1, 8):
        g, sig = [], []
        for _ in range(300):
            y = rng.standard_normal(n)
            x = rng.standard_normal((n, k))
            sse0 = float(np.sum(y * y))
            sse1 = float(np.sum((y - x @ np.linalg.lstsq(x, y, rcond=None)[0]) ** 2))
            g.append(1 - np.sqrt(sse1 / sse0))
            sig.append(significance(sse0, sse1, n, k, k) < 0.05)
        gain[k], rate[k] = float(np.mean(g)), float(np.mean(sig))
    assert gain[8] > 4 * gain[1]  # flexibility alone buys the richer family a larger gain on noise ...
    assert abs(rate[8] - rate[1]) < 0.05 and rate[8] < 0.09  # ... but no more significant gains


def test_counting_all_fitted_parameters_matters():
    """With 40 parameters fitted on 120 samples, N − k in the denominator declares noise significant far too
    often; N − k_total keeps the nominal rate."""
    p_total = _p_values(120, 40, 2, 300, seed=11)
    p_extra = _p_values(120, 40, 2, 300, seed=11, total=False)
    assert 0.02 <= float(np.mean(p_total < 0.05)) <= 0.09
    assert float(np.mean(p_extra < 0.05)) > 1.5 * float(np.mean(p_total < 0.05))
