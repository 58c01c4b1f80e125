"""Residual analysis (dissertation §2.8): the five correlation tests of eq. 2-32, residual spectrum, normality.

For an unbiased model the one-step residuals ξ(t) are unpredictable from past inputs and outputs
(Billings & Voon 1986), i.e. (eq. 2-32)

    φ_ξξ(τ) = δ(τ),  φ_uξ(τ) = 0 ∀τ,  φ_ξ(ξu)(τ) = 0 τ ≥ 0,  φ_(u²)'ξ(τ) = 0 ∀τ,  φ_(u²)'ξ²(τ) = 0 ∀τ,

with (u²)' = u² − mean(u²) and the normalised cross-correlation of eq. 2-33. Under the null hypothesis each
φ(τ) ≈ N(0, 1/N), so the 95 % band is ±1.96/√N — with N the number of samples, not 2N − 1 (a band of
1.96/√(2N−1) is √2 too narrow and flags 12–14 % of the lags of white noise instead of 5 %).

Each test reports the lags outside the pointwise band (``failing_lags``; about 5 % of the lags of white noise
fall there by chance) and a decision ``passed`` that accounts for testing many lags at once: a test fails when
any |φ(τ)| exceeds the Bonferroni band z_{1−α/(2m)}/√N over its m lags, or when more lags fall outside the
pointwise band than a Binomial(m, α) count would give with probability 1 − α. Each of the two checks of each
of the five tests runs at level α/10, so a white residual passes all five with probability ≈ 1 − α.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal, stats

from sysid.errors import DataError

__all__ = [
    "xcorr",
    "correlation_tests",
    "tests_summary",
    "residual_spectrum",
    "normality",
    "ar_prewhiten",
    "periodicity_test",
    "line_test",
]


def _vector(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.ndim == 2 and a.shape[1] == 1:
        a = a[:, 0]
    if a.ndim != 1:
        raise DataError(f"{name} must be one signal (1-D), got shape {a.shape}; test each channel separately")
    if a.size < 3:
        raise DataError(f"{name} has {a.size} samples, too few for correlation tests")
    if not np.isfinite(a).all():
        raise DataError(f"{name} has non-finite (NaN/inf) samples")
    return a


def xcorr(x: np.ndarray, y: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """Normalised cross-correlation of eq. 2-33, φ_xy(τ) = Σ_t (x(t)−x̄)(y(t+τ)−ȳ) / √(Σ(x−x̄)² Σ(y−ȳ)²).

    Negative τ pairs x(t) with y(t − |τ|). Computed with FFTs (O(N log N)). A constant signal gives zeros.
    """
    x = np.asarray(x, float) - np.mean(x)
    y = np.asarray(y, float) - np.mean(y)
    n = x.size
    den = np.sqrt(np.dot(x, x) * np.dot(y, y))
    if den == 0.0:
        return np.zeros(len(lags))
    nfft = 1 << int(np.ceil(np.log2(2 * n - 1)))
    c = np.fft.irfft(np.conj(np.fft.rfft(x, nfft)) * np.fft.rfft(y, nfft), nfft)
    # c[τ] = Σ_t x(t) y(t+τ) for τ ≥ 0; c[nfft+τ] for τ < 0
    lags = np.asarray(lags, dtype=int)
    return c[np.where(lags >= 0, lags, nfft + lags)] / den


def correlation_tests(e, u, max_lag: int = 20, alpha: float = 0.05) -> dict[str, Any]:
    """The five residual correlation tests of eq. 2-32 on residuals ``e`` and input ``u`` (1-D, same length).

    Returns ``{"passed": bool, "n": N, "band": z/√N, "tests": [{name, passed, failing_lags, lags, values, band,
    fraction_outside}]}``. Test names: ``r_ee`` (τ = 1..max_lag), ``r_ue`` (τ = −max_lag..max_lag),
    ``r_e(eu)`` (τ = 0..max_lag, φ between ξ(t) and ξ(t−1−τ)u(t−1−τ)), ``r_u2'e`` and ``r_u2'e2``
    (τ = −max_lag..max_lag).
    """
    e = _vector(e, "residuals e")
    u = _vector(u, "input u")
    if e.size != u.size:
        raise DataError(f"residuals and input have unequal lengths ({e.size} and {u.size})")
    max_lag = int(max_lag)
    if not 1 <= max_lag < e.size - 1:
        raise DataError(f"max_lag must lie in 1..{e.size - 2}, got {max_lag}")
    if not 0.0 < alpha < 1.0:
        raise DataError(f"alpha must lie in (0, 1), got {alpha}")
    n = e.size
    z = stats.norm.ppf(1.0 - alpha / 2.0)
    band = z / np.sqrt(n)
    both = np.arange(-max_lag, max_lag + 1)
    pos = np.arange(1, max_lag + 1)
    u2 = u**2 - np.mean(u**2)
    e2 = e**2 - np.mean(e**2)
    # φ_ξ(ξu)(τ): E[ξ(t) · ξ(t−1−τ) u(t−1−τ)], τ ≥ 0  ⇔ correlation of (ξu) at t with ξ at t + 1 + τ
    eu = e * u
    defs = [
        ("r_ee", e, e, pos, pos),
        ("r_ue", u, e, both, both),
        ("r_e(eu)", eu, e, np.arange(0, max_lag + 1) + 1, np.arange(0, max_lag + 1)),
        ("r_u2'e", u2, e, both, both),
        ("r_u2'e2", u2, e2, both, both),
    ]
    tests = []
    for name, a, b, lags, shown in defs:
        vals = xcorr(a, b, lags)
        out = np.abs(vals) > band
        m = len(lags)
        a_check = alpha / (2.0 * len(defs))  # two checks per test, five tests: family-wise level ≈ alpha
        z_fw = stats.norm.ppf(1.0 - a_check / (2.0 * m))
        max_count = int(stats.binom.ppf(1.0 - a_check, m, alpha))
        passed = bool(np.all(np.abs(vals) <= z_fw / np.sqrt(n)) and out.sum() <= max_count)
        tests.append(
            {
                "name": name,
                "passed": passed,
                "failing_lags": [int(t) for t in shown[out]],
                "lags": [int(t) for t in shown],
                "values": vals.tolist(),
                "band": float(band),
                "fraction_outside": float(out.mean()),
            }
        )
    return {
        "passed": all(t["passed"] for t in tests),
        "n": int(n),
        "band": float(band),
        "alpha": float(alpha),
        "tests": tests,
    }


def tests_summary(ct: dict[str, Any]) -> dict[str, Any]:
    """Compact form of a :func:`correlation_tests` result for JSON output: per test, passed, the number of
    failing lags, the first 40 failing lags, the largest |φ| and the band (the values themselves are left out)."""
    return {
        "passed": bool(ct.get("passed")),
        "tests": [
            {
                "name": t["name"],
                "passed": bool(t["passed"]),
                "n_failing": len(t.get("failing_lags", [])),
                "failing_lags": [int(v) for v in t.get("failing_lags", [])][:40],
                "max_abs": float(np.max(np.abs(t["values"]))) if len(t.get("values", [])) else 0.0,
                "band": float(np.atleast_1d(t.get("band", 0.0))[0]) if np.ndim(t.get("band", 0.0)) <= 1 else None,
            }
            for t in ct.get("tests", [])
        ],
    }


def residual_spectrum(e, fs: float, nperseg: int | None = None) -> dict[str, Any]:
    """Welch power spectral density of the residuals [units²/Hz] and its flatness.

    ``flatness`` is the spectral flatness (geometric / arithmetic mean of the PSD, 1 for white noise, → 0 for
    coloured residuals); ``peak_hz`` the frequency of the largest PSD value (e.g. an unmodelled resonance).
    """
    e = _vector(e, "residuals e")
    if not (np.isfinite(fs) and fs > 0):
        raise DataError(f"fs must be positive, got {fs}")
    nper = int(nperseg or min(e.size, 1024))
    f, p = signal.welch(e, fs=fs, nperseg=nper)
    pp = p[1:] if p.size > 1 else p
    pos = pp[pp > 0]
    flat = float(np.exp(np.mean(np.log(pos))) / np.mean(pos)) if pos.size else float("nan")
    return {"f_hz": f, "psd": p, "flatness": flat, "peak_hz": float(f[int(np.argmax(p))])}


def normality(e, alpha: float = 0.05) -> dict[str, Any]:
    """D'Agostino–Pearson K² test of normality of the residuals (scipy.stats.normaltest).

    Returns ``{passed, p_value, statistic, skewness, excess_kurtosis}``; ``passed`` when p ≥ alpha.
    """
    e = _vector(e, "residuals e")
    if e.size < 8:
        raise DataError(f"normality test needs at least 8 samples, got {e.size}")
    stat, p = stats.normaltest(e)
    return {
        "passed": bool(p >= alpha),
        "p_value": float(p),
        "statistic": float(stat),
        "skewness": float(stats.skew(e)),
        "excess_kurtosis": float(stats.kurtosis(e)),
    }


def ar_prewhiten(x, max_order: int, select: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Innovations of an AR model of ``x`` fitted by least squares, and its coefficients a (x(t) ≈ Σ a_k x(t−k)).

    ``select``: the order minimising BIC (N ln σ̂² + p ln N) over 1 … ``max_order``; else ``max_order`` itself.
    Prewhitening (Box & Jenkins; Ljung, *System Identification*, 2nd ed., §16.6) turns a coloured series into one
    whose sample statistics have their white-noise distributions. Returns (ε of length N − p, a), x mean-removed.
    """
    x = _vector(x, "series x")
    x = x - x.mean()
    n = x.size
    top = int(min(max_order, max(n // 10, 1)))
    best: tuple[float, np.ndarray, np.ndarray] | None = None
    for p in range(1, top + 1) if select else [top]:
        X = np.column_stack([x[p - k : n - k] for k in range(1, p + 1)])
        a = np.linalg.lstsq(X, x[p:], rcond=None)[0]
        eps = x[p:] - X @ a
        bic = eps.size * np.log(max(float(np.mean(eps * eps)), 1e-300)) + p * np.log(eps.size)
        if best is None or bic < best[0]:
            best = (float(bic), eps, a)
    assert best is not None
    return best[1], best[2]


def periodicity_test(e) -> dict[str, Any]:
    """Fisher's g test for a hidden periodic component in a white series (Fisher 1929; Brockwell & Davis,
    *Time Series*, §10.2): g = the largest periodogram ordinate over their sum (0 < f < fs/2, m ordinates),
    P(G > g) = Σ_{j=1}^{⌊1/g⌋} (−1)^{j−1} C(m, j) (1 − j g)^{m−1} under white Gaussian noise. Coloured series:
    prewhiten first (:func:`ar_prewhiten`). Returns ``{p_value, g, m, index}`` (``index``: the ordinate's bin)."""
    e = _vector(e, "series e")
    e = e - e.mean()
    per = np.abs(np.fft.rfft(e)) ** 2
    per = per[1 : (e.size - 1) // 2 + 1]  # 0 < f < fs/2
    m = per.size
    tot = float(per.sum())
    if m < 2 or tot <= 0:
        return {"p_value": 1.0, "g": 0.0, "m": m, "index": None}
    k = int(np.argmax(per))
    g = float(per[k]) / tot
    # the alternating sum: its terms shrink fast for small g; the first term alone is a tight upper bound
    p = 0.0
    for j in range(1, min(int(1.0 / g), 50) + 1):
        p += (-1) ** (j - 1) * float(np.exp(_log_comb(m, j) + (m - 1) * np.log1p(-j * g)))
    return {"p_value": float(min(max(p, 0.0), 1.0)), "g": g, "m": m, "index": k + 1}


def _log_comb(n: int, k: int) -> float:
    return math.lgamma(n + 1) - math.lgamma(k + 1) - math.lgamma(n - k + 1)


#: zero-padding of :func:`line_test`'s transforms: a line lies within ⅛ bin of a tested frequency
PAD_LINE_TEST = 4


def line_test(e, nw: float = 4.0) -> dict[str, Any]:
    """Thomson's harmonic F-test for a sinusoidal line in coloured noise (Thomson 1982, *Proc. IEEE* 70, §XIII;
    Percival & Walden, *Spectral Analysis for Physical Applications*, §10.11): with the K = 2·NW − 1 Slepian tapers
    v_k, their transforms Y_k(f) and U_k = Σ_t v_k(t), the line's amplitude μ(f) = Σ U_k Y_k / Σ U_k² and
    F(f) = (K − 1)·|μ|²·Σ U_k² / Σ |Y_k − μ·U_k|², distributed F(2, 2K − 2) where the spectrum is smooth over the
    bandwidth ±W = ±NW/N. It needs no prewhitening: an AR model fitted to a series absorbs a line (two poles on the
    unit circle predict a sinusoid exactly), which leaves Fisher's g (:func:`periodicity_test`) blind to a hum.
    The smallest p over a grid :data:`PAD_LINE_TEST` times finer than the Fourier frequencies in (W, ½ − W) cycles
    per sample, Bonferroni-multiplied by the grid's size. Returns ``{p_value, F, index}`` (``index``: the
    frequency in bins of the length-N transform, a multiple of 1/PAD_LINE_TEST)."""
    e = _vector(e, "series e")
    n = e.size
    k = max(int(round(2 * nw)) - 1, 2)
    if n < 8 * nw:
        return {"p_value": 1.0, "F": 0.0, "index": None}
    tapers = signal.windows.dpss(n, nw, Kmax=k)  # (K, N), unit energy
    pad = PAD_LINE_TEST  # a line half a bin from every Fourier frequency leaks into the odd tapers: a finer grid
    y = np.fft.rfft(tapers * (e - e.mean()), n=pad * n, axis=1)  # (K, pad·N/2 + 1)
    u0 = tapers.sum(axis=1)  # U_k(0): zero for the odd tapers
    su2 = float(u0 @ u0)
    mu = (u0 @ y) / su2
    resid = np.sum(np.abs(y - np.outer(u0, mu)) ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        F = (k - 1) * np.abs(mu) ** 2 * su2 / resid
    lo = pad * (int(math.ceil(nw)) + 1)  # within W of 0 or of ½ cycle per sample the test is not valid
    hi = pad * ((n - 1) // 2 - int(math.ceil(nw)))
    if hi <= lo:
        return {"p_value": 1.0, "F": 0.0, "index": None}
    band = np.nan_to_num(F[lo:hi], nan=0.0, posinf=np.finfo(float).max)
    i = int(np.argmax(band))
    p = float(stats.f.sf(band[i], 2, 2 * k - 2))
    return {"p_value": float(min(1.0, p * band.size)), "F": float(band[i]), "index": (lo + i) / pad}
