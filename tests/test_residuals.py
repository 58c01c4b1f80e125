"""Residual correlation tests (eq. 2-32/2-33), spectrum and normality."""

import numpy as np
import pytest

from sysid.errors import DataError
from sysid.evaluation.residuals import correlation_tests, normality, residual_spectrum, xcorr
from sysid.evaluation.residuals import tests_summary as summary  # (a name starting with "test" would be collected)


def test_xcorr_matches_eq_2_33_directly():
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal(300), rng.standard_normal(300)
    xm, ym = x - x.mean(), y - y.mean()
    den = np.sqrt(np.sum(xm**2) * np.sum(ym**2))
    lags = np.array([-7, -1, 0, 1, 5, 20])
    want = [np.sum(xm[: 300 - t] * ym[t:]) / den if t >= 0 else np.sum(xm[-t:] * ym[: 300 + t]) / den for t in lags]
    np.testing.assert_allclose(xcorr(x, y, lags), want, atol=1e-12)


def test_summary_keeps_the_decisions_and_counts_without_the_curves():
    rng = np.random.default_rng(3)
    e = rng.standard_normal(500)
    r = correlation_tests(np.r_[e[:1], e[1:] + 0.8 * e[:-1]], rng.uniform(-1, 1, 500), max_lag=10)
    s = summary(r)
    assert s["passed"] == r["passed"] and [t["name"] for t in s["tests"]] == [t["name"] for t in r["tests"]]
    for full, short in zip(r["tests"], s["tests"]):
        assert short["n_failing"] == len(full["failing_lags"]) and short["failing_lags"] == full["failing_lags"][:40]
        assert short["max_abs"] == pytest.approx(np.max(np.abs(full["values"]))) and short["band"] == r["band"]
        assert "values" not in short
    assert not s["tests"][0]["passed"]  # the coloured residual fails r_ee


def test_white_noise_about_five_percent_outside_the_band():
    fractions, passed = [], 0
    n = 4000
    for seed in range(30):
        rng = np.random.default_rng(seed)
        r = correlation_tests(rng.standard_normal(n), rng.uniform(-1, 1, n), max_lag=30)
        assert r["band"] == pytest.approx(1.959964 / np.sqrt(n), rel=1e-6)
        fractions += [t["fraction_outside"] for t in r["tests"]]
        passed += r["passed"]
    frac = float(np.mean(fractions))
    # ~30 seeds x 5 tests x ~50 lags: the binomial sd of the fraction is ~0.0025
    assert 0.04 < frac < 0.06, frac  # not 12-14 % as a 1.96/sqrt(2N-1) band gives
    assert passed >= 26  # family-wise level 5 %: most white residuals pass all five tests


def test_each_test_detects_its_own_kind_of_dependence():
    rng = np.random.default_rng(1)
    n = 3000
    u = rng.uniform(-1, 1, n)
    w = rng.standard_normal(n)
    names = ["r_ee", "r_ue", "r_e(eu)", "r_u2'e", "r_u2'e2"]

    def failing(e):
        r = correlation_tests(e, u, max_lag=10)
        return {t["name"] for t in r["tests"] if not t["passed"]}, {t["name"]: t for t in r["tests"]}

    coloured = w + 0.6 * np.r_[0, w[:-1]]  # MA(1): r_ee at lag 1
    f, t = failing(coloured)
    assert "r_ee" in f and 1 in t["r_ee"]["failing_lags"]
    linear_u = w + 0.5 * np.r_[0, 0, 0, u[:-3]]  # unmodelled u(t-3)
    f, t = failing(linear_u)
    assert "r_ue" in f and 3 in t["r_ue"]["failing_lags"]
    quad_u = w + 1.0 * (np.r_[0, 0, u[:-2]] ** 2 - 1 / 3)  # unmodelled u(t-2)^2
    f, t = failing(quad_u)
    assert "r_u2'e" in f and 2 in t["r_u2'e"]["failing_lags"] and "r_ue" not in f
    cross = w + 0.8 * np.r_[0, w[:-1] * u[:-1]]  # unmodelled e(t-1) u(t-1)
    f, t = failing(cross)
    assert "r_e(eu)" in f and 0 in t["r_e(eu)"]["failing_lags"]
    hetero = w * (1 + 1.5 * np.r_[0, u[:-1] ** 2])  # variance depends on u(t-1)^2
    f, t = failing(hetero)
    assert "r_u2'e2" in f and 1 in t["r_u2'e2"]["failing_lags"]
    assert set(names) == set(t)


def test_spectrum_and_normality():
    rng = np.random.default_rng(2)
    w = rng.standard_normal(8192)
    s_white = residual_spectrum(w, fs=1000.0)
    s_col = residual_spectrum(np.convolve(w, np.ones(8) / 8, mode="same"), fs=1000.0)
    assert s_white["flatness"] > 0.8 > s_col["flatness"]
    assert s_white["f_hz"][-1] == pytest.approx(500.0)
    # Parseval: the integral of the one-sided PSD is the variance
    assert np.trapezoid(s_white["psd"], s_white["f_hz"]) == pytest.approx(np.var(w), rel=0.05)
    assert normality(w)["passed"]
    assert not normality(rng.exponential(size=4000))["passed"]


def test_bad_input():
    with pytest.raises(DataError, match="unequal"):
        correlation_tests(np.ones(100), np.ones(99))
    with pytest.raises(DataError, match="non-finite"):
        correlation_tests(np.r_[np.nan, np.ones(99)], np.ones(100))
    with pytest.raises(DataError, match="max_lag"):
        rng = np.random.default_rng(0)
        correlation_tests(rng.standard_normal(10), rng.standard_normal(10), max_lag=50)


def test_ar_prewhitening_recovers_an_ar1_pole_and_whitens_it():
    from sysid.evaluation.residuals import ar_prewhiten

    rng = np.random.default_rng(3)
    w = rng.standard_normal(20_000)
    x = np.zeros_like(w)
    for t in range(1, w.size):
        x[t] = 0.9 * x[t - 1] + w[t]
    eps, a = ar_prewhiten(x, 10)
    assert a.size == 1 and a[0] == pytest.approx(0.9, abs=0.01)  # BIC picks the true order
    assert np.std(eps) == pytest.approx(1.0, rel=0.02)  # the innovations' unit variance
    eps5, a5 = ar_prewhiten(x, 5, select=False)
    assert a5.size == 5 and eps5.size == x.size - 5


def test_fisher_periodicity_test_holds_its_level_and_finds_a_line():
    from sysid.evaluation.residuals import periodicity_test

    rng = np.random.default_rng(4)
    p = np.array([periodicity_test(rng.standard_normal(1001))["p_value"] for _ in range(1000)])
    # under white noise P(p < α) = α: 1000 draws at α = 0.05 lie within 0.05 ± 3·0.007
    assert 0.029 < np.mean(p < 0.05) < 0.071
    t = np.arange(4000)
    line = periodicity_test(rng.standard_normal(4000) + 0.2 * np.sin(2 * np.pi * 0.1234 * t))
    assert line["p_value"] < 1e-6 and line["index"] == round(0.1234 * 4000)


def test_thomson_line_test_holds_its_level_in_coloured_noise_and_finds_a_strong_line():
    from scipy import signal

    from sysid.evaluation.residuals import ar_prewhiten, line_test, periodicity_test

    rng = np.random.default_rng(5)
    ar1 = [signal.lfilter([1.0], [1.0, -0.9], rng.standard_normal(1500))[500:] for _ in range(300)]
    p = np.array([line_test(x)["p_value"] for x in ar1])
    # Bonferroni over the grid is conservative: P(p < 0.05) ≤ 0.05, 300 draws → below 0.05 + 3·0.013
    assert np.mean(p < 0.05) < 0.09
    t = np.arange(4000)
    x = signal.lfilter([1.0], [1.0, -0.8], rng.standard_normal(4000))
    x = x / np.std(x) + 5.0 * np.sqrt(2.0) * np.sin(2 * np.pi * 0.02135 * t)  # 85.4 bins: off the Fourier grid
    line = line_test(x)
    assert line["p_value"] < 1e-4 and abs(line["index"] - 0.02135 * 4000) <= 0.25
    eps, _ = ar_prewhiten(x, 10)  # the AR model predicts the line: Fisher's g after it does not see it
    assert periodicity_test(eps)["p_value"] > line["p_value"] * 1e3
