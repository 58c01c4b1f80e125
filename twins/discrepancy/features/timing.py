"""Time-domain residual features: effective sample count, trends, creep after steps, lag regressions (echoes),
delays, and the residual–input correlation before the model's first arrival (electrical paths).

Every function takes plain arrays and an explicit sampling rate ``fs`` [Hz] and returns numbers.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import signal as sps

__all__ = [
    "effective_samples",
    "trend",
    "step_drift",
    "lag_regression",
    "delay_estimate",
    "delay_candidates",
    "io_delay",
    "early_input_correlation",
]


def _z(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    x = x - x.mean()
    s = x.std()
    return x / s if s > 0 else x


def effective_samples(e: np.ndarray, max_lag: int | None = None) -> float:
    """Effective number of independent samples of a residual for variance statistics.

    N_eff = N / (1 + 2 Σ_{k=1..K} ρ_k²) (Bartlett's variance of a sample variance of a Gaussian process with
    autocorrelation ρ_k), K = min(N/10, 500) by default so that slow correlations (quantisation error of a slow
    signal, drifts) count; white noise gives N_eff ≈ N − 2K, a strongly coloured residual far fewer.
    """
    if max_lag is None:
        max_lag = int(min(max(np.asarray(e).size // 10, 1), 500))
    e = np.asarray(e, dtype=float)
    n = e.size
    if n < 4:
        return float(n)
    ez = e - e.mean()
    K = int(min(max_lag, n // 4))
    f = np.fft.rfft(ez, 2 * n)
    ac = np.fft.irfft(f * np.conj(f))[: K + 1]
    if ac[0] <= 0:
        return float(n)
    rho = ac[1:] / ac[0]
    return float(n / (1.0 + 2.0 * np.sum(rho**2)))


def trend(e: np.ndarray, fs: float) -> dict[str, float]:
    """Linear trend of the residual: slope [unit/s], total drift over the record, share of residual power.

    ``drift_share`` is the fraction of the residual's variance explained by a straight line plus a
    quadratic in time; near 0 for a stationary residual, near 1 for a pure drift.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    t = np.arange(n) / fs
    tc = (t - t.mean()) / max(t.std(), 1e-300)
    A = np.column_stack([np.ones(n), tc, tc**2 - 1.0])
    coef, *_ = np.linalg.lstsq(A, e, rcond=None)
    fit = A @ coef
    var = float(np.var(e)) or 1e-300
    slope = float(coef[1] / max(t.std(), 1e-300))
    return {
        "slope_per_s": slope,
        "drift_total": float(fit[-1] - fit[0]),
        "offset": float(coef[0]),
        "drift_share": float(np.var(fit - fit.mean()) / var),
    }


def step_drift(
    u: np.ndarray, e: np.ndarray, fs: float, min_hold_s: float = 0.05, rel_step: float = 0.2
) -> dict[str, Any]:
    """Slow residual drift after input steps, as creep would leave it.

    Steps are jumps of the input larger than ``rel_step`` of its range followed by a hold of at least
    ``min_hold_s``. For each hold the residual is regressed on ``Δu·log10(t/t0)`` (t from the step, t0 one
    sample-span ``10/fs``); ``gain_per_decade`` is the common coefficient [y-unit per input-unit per decade]
    and ``share`` the fraction of the in-hold residual variance it explains.
    """
    u = np.asarray(u, dtype=float)
    e = np.asarray(e, dtype=float)
    span = float(np.ptp(u)) or 1.0
    du = np.diff(u)
    idx = np.flatnonzero(np.abs(du) > rel_step * span) + 1
    if idx.size == 0:
        return {"n_steps": 0, "gain_per_decade": 0.0, "share": 0.0}
    bounds = list(idx) + [u.size]
    xs, es = [], []
    t0 = 10.0 / fs
    n_used = 0
    for a, b in zip(bounds[:-1], bounds[1:]):
        if (b - a) / fs < min_hold_s:
            continue
        if np.ptp(u[a:b]) > 0.05 * span:  # not a hold
            continue
        jump = u[a] - u[a - 1]
        t = np.arange(b - a) / fs + 1.0 / fs
        x = jump * np.log10(np.maximum(t, t0) / t0)
        seg = e[a:b]
        xs.append(x - x.mean())
        es.append(seg - seg.mean())
        n_used += 1
    if not xs:
        return {"n_steps": 0, "gain_per_decade": 0.0, "share": 0.0}
    x = np.concatenate(xs)
    r = np.concatenate(es)
    k = float(x @ r / max(x @ x, 1e-300))
    share = float(1.0 - np.var(r - k * x) / max(np.var(r), 1e-300))
    return {"n_steps": n_used, "gain_per_decade": k, "share": share}


def lag_regression(
    e: np.ndarray, ref: np.ndarray, fs: float, max_lag_s: float | None = None, min_lag: int = 0
) -> dict[str, Any]:
    """Regression coefficient of the residual on the reference delayed by each lag, c(τ) = Σe·r(t−τ)/Σr².

    For an unmodelled echo ``y = y₀ + a·y₀(t−τ)`` and ``ref = ŷ ≈ y₀`` the peak of |c| sits at the echo's delay
    with c ≈ a (when the reference's own autocorrelation has decayed at τ). The peak is searched at lags
    ``≥ min_lag`` samples; it is scored against the spread of c over all lags (a robust z-score), and its
    delay refined by a parabola through the envelope of c.
    """
    e = np.asarray(e, dtype=float) - np.mean(e)
    r = np.asarray(ref, dtype=float) - np.mean(ref)
    n = e.size
    L = n // 2 if max_lag_s is None else int(min(n // 2, round(max_lag_s * fs)))
    m = 1 << int(np.ceil(np.log2(2 * n)))
    c = np.fft.irfft(np.fft.rfft(e, m) * np.conj(np.fft.rfft(r, m)), m)[: L + 1] / max(float(r @ r), 1e-300)
    env = np.abs(sps.hilbert(c)) if c.size > 8 else np.abs(c)
    lo = int(min(max(min_lag, 0), L))
    seg = env[lo:]
    if seg.size == 0:
        return {"lag_s": float("nan"), "coef": 0.0, "z": 0.0, "lag_samples": 0}
    k = int(np.argmax(seg)) + lo
    mad = float(np.median(np.abs(env - np.median(env)))) * 1.4826 or 1e-300
    zscore = float((env[k] - np.median(env)) / mad)
    kk = float(k)
    if 0 < k < L:
        y0, y1, y2 = env[k - 1], env[k], env[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            kk = k + 0.5 * (y0 - y2) / den
    # the strongest envelope peaks at lags 4 … min_lag − 1 (candidates the search above skips)
    short = []
    if lo > 5:
        pk, _ = sps.find_peaks(env[4:lo])
        short = [float((p + 4) / fs) for p in pk[np.argsort(env[4:lo][pk])[::-1][:3]]]
    return {
        "lag_s": kk / fs,
        "lag_samples": int(k),
        "coef": float(c[k]),
        "envelope": float(env[k]),
        "z": zscore,
        "short_lags_s": short,
    }


def _shift(x: np.ndarray, d: float) -> np.ndarray:
    """x delayed by d samples (fractional, linear interpolation; zeros shifted in)."""
    n = x.size
    return np.interp(np.arange(n) - d, np.arange(n), x, left=x[0], right=x[-1])


def delay_estimate(y: np.ndarray, ysim: np.ndarray, fs: float, max_shift_s: float | None = None) -> dict[str, float]:
    """Shift [s] of the measured output relative to the simulated one (positive: measurement arrives later).

    Integer start at the peak of the cross-correlation of y and ŷ, then Gauss–Newton on the fractional shift d
    and a gain g minimising Σ(y − g·ŷ(t − d))² (the derivative of the shifted simulation as the sensitivity).
    ``corr`` is the correlation of y with the aligned simulation, ``gain`` the fitted g.
    """
    y = np.asarray(y, float) - np.mean(y)
    s = np.asarray(ysim, float) - np.mean(ysim)
    n = y.size
    L = n // 4 if max_shift_s is None else int(min(n // 2, max(1, round(max_shift_s * fs))))
    m = 1 << int(np.ceil(np.log2(2 * n)))
    xc = np.fft.irfft(np.fft.rfft(y, m) * np.conj(np.fft.rfft(s, m)), m)
    lags = np.r_[np.arange(0, L + 1), np.arange(-L, 0)]
    vals = np.r_[xc[: L + 1], xc[m - L :]]
    d = float(lags[int(np.argmax(vals))])
    g = 1.0
    for _ in range(8):
        sh = _shift(s, d)
        ds = np.gradient(sh)
        A = np.column_stack([sh, -g * ds])
        try:
            (g_new, dd), *_ = np.linalg.lstsq(A, y, rcond=None)
        except np.linalg.LinAlgError:
            break
        g = float(g_new) if np.isfinite(g_new) and g_new != 0 else g
        dd = float(np.clip(dd, -1.0, 1.0))
        d += dd
        if abs(dd) < 1e-4:
            break
    sh = _shift(s, d)
    den = float(np.sqrt((y @ y) * (sh @ sh))) or 1e-300
    return {"shift_s": d / fs, "shift_samples": d, "corr": float(y @ sh) / den, "gain": g}


def delay_candidates(
    y: np.ndarray, ysim: np.ndarray, fs: float, max_shift_s: float | None = None, k: int = 3
) -> list[float]:
    """Shifts [s] of y relative to ŷ at the ``k`` highest peaks of their cross-correlation, each refined to a
    fraction of a sample (parabola). For narrow-band signals the carrier cycle is ambiguous: the caller tries
    each."""
    y = np.asarray(y, float) - np.mean(y)
    s = np.asarray(ysim, float) - np.mean(ysim)
    n = y.size
    if not np.any(s) or not np.any(y):
        return []
    L = n // 4 if max_shift_s is None else int(min(n // 2, max(2, round(max_shift_s * fs))))
    m = 1 << int(np.ceil(np.log2(2 * n)))
    xc = np.fft.irfft(np.fft.rfft(y, m) * np.conj(np.fft.rfft(s, m)), m)
    vals = np.r_[xc[m - L :], xc[: L + 1]]
    lags = np.arange(-L, L + 1)
    pk, _ = sps.find_peaks(vals)
    if pk.size == 0:
        return []
    pk = pk[np.argsort(vals[pk])[::-1][:k]]
    out = []
    for i in pk:
        d = float(lags[i])
        if 0 < i < vals.size - 1:
            a, b, c = vals[i - 1], vals[i], vals[i + 1]
            den = a - 2 * b + c
            if den < 0:
                d += 0.5 * (a - c) / den
        out.append(d / fs)
    return out


def io_delay(u: np.ndarray, y: np.ndarray, fs: float, max_shift_s: float | None = None) -> float:
    """Input–output delay [s]: lag of the peak of the envelope of the u–y cross-correlation (≥ 0)."""
    u = _z(u)
    y = _z(y)
    n = u.size
    L = n // 4 if max_shift_s is None else int(min(n // 2, max(1, round(max_shift_s * fs))))
    m = 1 << int(np.ceil(np.log2(2 * n)))
    xc = np.fft.irfft(np.fft.rfft(y, m) * np.conj(np.fft.rfft(u, m)), m)[: L + 1]
    env = np.abs(sps.hilbert(xc)) if xc.size > 8 else np.abs(xc)
    return float(np.argmax(env) / fs)


def early_input_correlation(e: np.ndarray, u: np.ndarray, ysim: np.ndarray, fs: float) -> dict[str, Any]:
    """Residual–input correlation before the model's first arrival (electrical paths, e.g. crosstalk).

    ``first_arrival_s`` is :func:`io_delay` of the simulated output (the lag of the u–ŷ correlation envelope's
    peak: a time of flight). The normalised cross-correlation r(k) = Σe(t)u(t−k)/√(Σe²Σu²) is searched for its
    largest |r| at lags 0 ≤ k < first arrival / 2, where no acoustic (delayed) path of the model contributes.
    Its null level is the RMS of r at the *negative* lags −first…−first/2 (the residual cannot depend on
    future input; there r only carries chance and u's own correlation), so ``ratio`` = peak / null RMS is about
    3–4 for a residual unrelated to u and grows with an early electrical path. Records whose model has no
    delay (first arrival < 8 samples) give ``valid: False``.
    """
    e = np.asarray(e, float) - np.mean(e)
    u = np.asarray(u, float) - np.mean(u)
    n = e.size
    k_first = int(round(io_delay(u, ysim, fs) * fs))
    if k_first < 8 or n < 4 * k_first or not np.any(e) or not np.any(u):
        return {"valid": False, "first_arrival_s": k_first / fs, "ratio": 0.0, "r_max": 0.0, "lag_s": 0.0}
    m = 1 << int(np.ceil(np.log2(2 * n)))
    xc = np.fft.irfft(np.fft.rfft(e, m) * np.conj(np.fft.rfft(u, m)), m) / np.sqrt(float(e @ e) * float(u @ u))
    early = np.abs(xc[: k_first // 2])
    null = xc[m - k_first : m - k_first // 2]
    null_rms = float(np.sqrt(np.mean(null**2))) or 1e-300
    late = np.abs(xc[k_first // 2 : min(3 * k_first, n // 2)])
    k = int(np.argmax(early))
    return {
        "valid": True,
        "first_arrival_s": k_first / fs,
        "lag_s": k / fs,
        "lag_samples": k,
        "r_max": float(early[k]),
        "null_rms": null_rms,
        "ratio": float(early[k] / null_rms),
        "r_late": float(late.max()) if late.size else 0.0,
        "early_over_late": float(early[k] / (late.max() if late.size and late.max() > 0 else 1e-300)),
    }
