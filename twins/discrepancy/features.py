"""Residual analysis of a twin's free-run simulation against measured data (issue 8, step 2).

Every function takes plain arrays and an explicit sampling rate ``fs`` [Hz] and returns numbers (dicts of
floats), in the manner of ``scipy.signal``. The residual is ``e = y - y_sim`` (measured minus simulated), as
the dissertation's eq. 2-30 writes ξ(t) = y(t) − ŷ(t).

What is measured, and which physical effect it points to:

- :func:`trend` — linear trend and slow drift of the residual (thermal drift, creep, offsets);
- :func:`step_drift` — slow residual drift after input steps, regressed on ``Δu·log10(t)`` (creep's
  logarithmic law, physics notes A.5);
- :func:`lag_regression` — regression of the residual on a delayed copy of a reference signal at every lag
  (reference = the simulated output or the input): a peak at lag τ > 0 is an echo (a delayed scaled copy,
  physics notes B.8) of amplitude ≈ the regression coefficient; a derivative-shaped peak at lag 0 is a delay;
- :func:`delay_estimate` — the sub-sample shift that best aligns the simulated output with the measured one
  (and the input–output delay from the cross-correlation of u and y);
- :func:`early_input_correlation` — residual–input cross-correlation at lags before the model's first arrival
  (a time of flight): a physical path there is electrical (crosstalk), the acoustic path has nothing yet;
- :func:`band_powers` — residual power inside and outside the band the input excites;
- :func:`product_bands` — for a band-pass input narrower than an octave, residual power where even-order
  products fall (difference band 0…B and sum band 2f₀…2f₁: outside the excited band) versus the excited band
  and the third-order skirts (the detection-line principle for a band instead of a line grid);
- :func:`harmonics` — residual power at the harmonics of a sine input (odd versus even);
- :func:`odd_even_lines` — power on the non-excited odd and even lines of a periodic (odd) multisine
  (odd-order versus even-order distortion, Pintelon & Schoukens' detection lines);
- :func:`nonlinear_correlation` — correlation of the residual with the parts of u², u³ (and ŷ², ŷ³) that are
  orthogonal to the linear terms (even- versus odd-order static nonlinearity);
- :func:`resonance_peaks` — narrow peaks of the residual spectrum (unmodelled resonances);
- :func:`quantization_step` — a lattice in the measured values (sensor / ADC quantisation);
- :func:`saturation_rails` — flat tops where the measurement saturates (an ADC or sensor at the end of its
  range) while the prediction goes beyond: the samples there are censored, not errors of the model;
- :func:`hysteresis_by_segment` — loop width and phase lag, measured versus simulated, per sine segment;
- :func:`correlation_tests` — the five tests of eq. 2-32 (``sysid.residuals``), with the failing lags.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import signal as sps
from scipy import stats

__all__ = [
    "trend", "step_drift", "lag_regression", "delay_estimate", "band_powers", "harmonics", "odd_even_lines",
    "nonlinear_correlation", "resonance_peaks", "quantization_step", "hysteresis_by_segment",
    "correlation_tests", "effective_samples", "analyse", "saturation_rails", "clip_to_rails",
    "early_input_correlation", "product_bands",
]


def _z(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    x = x - x.mean()
    s = x.std()
    return x / s if s > 0 else x


# ---------------------------------------------------------------------------------------------- statistics
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
    return float(n / (1.0 + 2.0 * np.sum(rho ** 2)))


# ---------------------------------------------------------------------------------------------- time domain
def trend(e: np.ndarray, fs: float) -> dict[str, float]:
    """Linear trend of the residual: slope [unit/s], total drift over the record, share of residual power.

    ``drift_share`` is the fraction of the residual's variance explained by a straight line plus a
    quadratic in time; near 0 for a stationary residual, near 1 for a pure drift.
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    t = np.arange(n) / fs
    tc = (t - t.mean()) / max(t.std(), 1e-300)
    A = np.column_stack([np.ones(n), tc, tc ** 2 - 1.0])
    coef, *_ = np.linalg.lstsq(A, e, rcond=None)
    fit = A @ coef
    var = float(np.var(e)) or 1e-300
    slope = float(coef[1] / max(t.std(), 1e-300))
    return {"slope_per_s": slope, "drift_total": float(fit[-1] - fit[0]), "offset": float(coef[0]),
            "drift_share": float(np.var(fit - fit.mean()) / var)}


def step_drift(u: np.ndarray, e: np.ndarray, fs: float, min_hold_s: float = 0.05, rel_step: float = 0.2) -> dict[str, Any]:
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


def lag_regression(e: np.ndarray, ref: np.ndarray, fs: float, max_lag_s: float | None = None,
                   min_lag: int = 0) -> dict[str, Any]:
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
    return {"lag_s": kk / fs, "lag_samples": int(k), "coef": float(c[k]), "envelope": float(env[k]), "z": zscore,
            "short_lags_s": short}


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
    vals = np.r_[xc[: L + 1], xc[m - L:]]
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


def delay_candidates(y: np.ndarray, ysim: np.ndarray, fs: float, max_shift_s: float | None = None,
                     k: int = 3) -> list[float]:
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
    vals = np.r_[xc[m - L:], xc[: L + 1]]
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
    null = xc[m - k_first: m - k_first // 2]
    null_rms = float(np.sqrt(np.mean(null ** 2))) or 1e-300
    late = np.abs(xc[k_first // 2: min(3 * k_first, n // 2)])
    k = int(np.argmax(early))
    return {"valid": True, "first_arrival_s": k_first / fs, "lag_s": k / fs, "lag_samples": k,
            "r_max": float(early[k]), "null_rms": null_rms, "ratio": float(early[k] / null_rms),
            "r_late": float(late.max()) if late.size else 0.0,
            "early_over_late": float(early[k] / (late.max() if late.size and late.max() > 0 else 1e-300))}


# ---------------------------------------------------------------------------------------------- frequency domain
def _psd(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    n = len(x)
    nper = int(min(n, max(256, 1 << int(np.log2(max(n // 8, 2))))))
    return sps.welch(np.asarray(x, dtype=float), fs=fs, nperseg=nper)


def excited_band(u: np.ndarray, fs: float, rel_db: float = -30.0) -> tuple[float, float]:
    """Frequency range [Hz] where the input's PSD lies within ``rel_db`` of its maximum."""
    f, p = _psd(u, fs)
    if not np.any(p > 0):
        return (0.0, 0.0)
    on = p >= p.max() * 10 ** (rel_db / 10)
    idx = np.flatnonzero(on)
    return float(f[idx[0]]), float(f[idx[-1]])


def band_powers(e: np.ndarray, u: np.ndarray, y: np.ndarray, fs: float) -> dict[str, float]:
    """Residual power inside and outside the excited band, absolute and relative to the output's power there.

    ``in_band_db`` / ``out_band_db``: 10·log10 of residual power ÷ output power in that band (how much of the
    output the simulation misses there); ``out_minus_in_db``: how much stronger the out-of-band residual is
    per Hz than the in-band one (distortion products and unmodelled resonances raise it).
    """
    f0, f1 = excited_band(u, fs)
    f, pe = _psd(e, fs)
    _, py = _psd(y, fs)
    inside = (f >= f0) & (f <= f1)
    outside = ~inside & (f > 0)
    pin = float(np.sum(pe[inside])) or 1e-300
    pout = float(np.sum(pe[outside])) or 1e-300
    yin = float(np.sum(py[inside])) or 1e-300
    yout = float(np.sum(py[outside])) or 1e-300
    dens_in = pin / max(inside.sum(), 1)
    dens_out = pout / max(outside.sum(), 1)
    return {"band_hz": [f0, f1], "in_band_db": 10 * np.log10(pin / yin), "out_band_db": 10 * np.log10(pout / yout),
            "out_minus_in_db": float(10 * np.log10(dens_out / dens_in)), "in_share": pin / (pin + pout)}


def product_bands(e: np.ndarray, u: np.ndarray, fs: float) -> dict[str, Any]:
    """Where the residual's power lies relative to the intermodulation bands of a band-pass input.

    For an input exciting [f₀, f₁] with f₁ < 2f₀ (less than an octave), second-order (even) products fall in
    the difference band (0, f₁−f₀] and the sum band [2f₀, 2f₁] — both outside the excited band — while
    third-order (odd) products fall in the excited band and its skirts [2f₀−f₁, f₀) ∪ (f₁, 2f₁−f₀]. Mean
    residual PSD densities are compared in dB with the quietest of these bands (the floor): ``even_db`` (the
    larger of the difference and sum band), ``in_db`` (the excited band) and ``skirt_db``. An even-order
    distortion raises ``even_db`` alone; an odd one or a linear error raises ``in_db``. ``valid`` is False for
    an input wider than an octave or bands that the sampling rate cannot hold.
    """
    f0, f1 = excited_band(u, fs)
    nyq = fs / 2.0
    if not (0 < f0 < f1 < 2 * f0) or 2 * f0 >= 0.98 * nyq:
        return {"valid": False, "even_db": 0.0, "in_db": 0.0, "skirt_db": 0.0}
    f, p = _psd(e, fs)
    b = f1 - f0
    guard = 0.02 * b

    def dens(lo: float, hi: float) -> float:
        sel = (f >= lo) & (f <= hi)
        return float(np.mean(p[sel])) if sel.sum() >= 2 else float("nan")

    bands = {"in": dens(f0 + guard, f1 - guard), "diff": dens(max(0.05 * b, f[1] if f.size > 1 else 0.0), b - guard),
             "sum": dens(2 * f0 + guard, min(2 * f1, 0.98 * nyq)),
             "skirt": np.nanmean([dens(2 * f0 - f1 + guard, f0 - guard), dens(f1 + guard, min(2 * f1 - f0, 2 * f0) - guard)])}
    vals = [v for v in bands.values() if np.isfinite(v) and v > 0]
    if len(vals) < 3:
        return {"valid": False, "even_db": 0.0, "in_db": 0.0, "skirt_db": 0.0}
    floor = min(vals)
    db = {k: (float(10 * np.log10(v / floor)) if np.isfinite(v) and v > 0 else 0.0) for k, v in bands.items()}
    return {"valid": True, "band_hz": [f0, f1], "even_db": max(db["diff"], db["sum"]), "diff_db": db["diff"],
            "sum_db": db["sum"], "in_db": db["in"], "skirt_db": db["skirt"]}


def harmonics(e: np.ndarray, u: np.ndarray, fs: float, n_harm: int = 5) -> dict[str, Any]:
    """Residual amplitude at the harmonics 2f…n·f of a (near-)sinusoidal input of fundamental f.

    Returns the fundamental, per-harmonic amplitudes and ``odd_over_even_db`` (power at 3f, 5f, … over 2f,
    4f, …): positive for odd-order (symmetric) distortion, negative for even-order (asymmetric).
    """
    u = np.asarray(u, dtype=float)
    n = u.size
    win = np.hanning(n)
    U = np.abs(np.fft.rfft((u - u.mean()) * win))
    E = np.abs(np.fft.rfft((np.asarray(e) - np.mean(e)) * win))
    freqs = np.fft.rfftfreq(n, 1 / fs)
    if U.size < 4:
        return {"f0_hz": float("nan"), "amplitudes": [], "odd_over_even_db": 0.0}
    k0 = int(np.argmax(U[1:])) + 1
    sine_like = U[k0] ** 2 / max(float(np.sum(U ** 2)), 1e-300)
    amps = []
    for h in range(1, n_harm + 1):
        k = h * k0
        if k + 2 >= E.size:
            break
        amps.append(float(np.max(E[max(k - 2, 0) : k + 3])) * 2 / win.sum())
    odd = sum(a ** 2 for i, a in enumerate(amps, 1) if i % 2 == 1 and i > 1)
    even = sum(a ** 2 for i, a in enumerate(amps, 1) if i % 2 == 0)
    return {"f0_hz": float(freqs[k0]), "sine_share": float(sine_like), "amplitudes": amps,
            "odd_over_even_db": float(10 * np.log10((odd + 1e-300) / (even + 1e-300)))}


def odd_even_lines(u: np.ndarray, y: np.ndarray, e: np.ndarray, fs: float, period: int | None = None,
                   rel_db: float = -40.0) -> dict[str, Any]:
    """Power on the excited, odd non-excited (detection) and even lines of a periodic multisine.

    The record (or its first whole number of periods of length ``period`` samples, averaged) is transformed;
    excited lines are those where the input's power is within ``rel_db`` of its maximum. Lines are indexed in
    units of the frequency resolution; with an odd multisine the excited lines are odd, so the non-excited
    odd lines inside the band collect odd-order distortion and the even lines even-order distortion.
    Powers are given for the measured output and for the residual, in dB relative to the mean excited-line
    power of y. ``odd_minus_even_db`` > 0 means odd-order distortion dominates.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    e = np.asarray(e, dtype=float)
    P = int(period) if period else u.size
    nper = u.size // P if P <= u.size else 0
    if nper < 1:
        return {"valid": False}
    def avg(x):
        return np.fft.rfft(x[: nper * P].reshape(nper, P).mean(axis=0))
    U, Y, E = avg(u), avg(y), avg(e)
    pu = np.abs(U) ** 2
    pu[0] = 0
    exc = pu >= pu.max() * 10 ** (rel_db / 10)
    ex_idx = np.flatnonzero(exc)
    if ex_idx.size < 3:
        return {"valid": False}
    # base grid: gcd of the excited lines
    g = int(np.gcd.reduce(ex_idx))
    lines = np.arange(U.size)
    on_grid = (lines % g == 0) & (lines > 0)
    m = lines // max(g, 1)
    lo, hi = ex_idx[0], ex_idx[-1]
    band = (lines >= lo) & (lines <= hi) & on_grid & ~exc
    odd_det = band & (m % 2 == 1)
    even_det = band & (m % 2 == 0)
    odd_grid = bool(np.all((ex_idx // g) % 2 == 1))
    ref = float(np.mean(np.abs(Y[exc]) ** 2)) or 1e-300
    def lvl(X, mask):
        return float(10 * np.log10((np.mean(np.abs(X[mask]) ** 2) if mask.any() else 0.0) / ref + 1e-30))
    out = {"valid": True, "odd_grid": odd_grid, "n_excited": int(exc.sum()), "n_odd_detection": int(odd_det.sum()),
           "n_even": int(even_det.sum()),
           "y_odd_db": lvl(Y, odd_det), "y_even_db": lvl(Y, even_det),
           "e_odd_db": lvl(E, odd_det), "e_even_db": lvl(E, even_det), "e_excited_db": lvl(E, exc)}
    out["odd_minus_even_db"] = (out["e_odd_db"] - out["e_even_db"]) if (odd_det.any() and even_det.any()) else 0.0
    return out


def _orth(x: np.ndarray, basis: list[np.ndarray]) -> np.ndarray:
    A = np.column_stack([np.ones_like(x)] + basis)
    c, *_ = np.linalg.lstsq(A, x, rcond=None)
    return x - A @ c


def nonlinear_correlation(e: np.ndarray, u: np.ndarray, ysim: np.ndarray, max_lag: int = 20) -> dict[str, float]:
    """Largest |cross-correlation| over lags 0…max_lag of the residual with the nonlinear parts of u and ŷ.

    ``u2`` / ``u3``: (u²)′ and (u³)′ made orthogonal to 1 and u (and u² for u³), the even and odd static
    nonlinearity of the input; ``y2`` / ``y3`` the same for the simulated output; ``lin`` the linear
    correlation with u. A symmetric (odd) compression correlates with the cubic part, an asymmetric
    (even) one with the square. Values are correlation coefficients; ``band`` is the 95 % white band 1.96/√N.
    """
    e = _z(e)
    n = e.size
    out = {"band": 1.96 / np.sqrt(n)}
    for name, x in (("u", _z(u)), ("y", _z(ysim))):
        x2 = _z(_orth(x ** 2, [x]))
        x3 = _z(_orth(x ** 3, [x, x ** 2]))
        for tag, s in (("lin", x), ("2", x2), ("3", x3)):
            m = 1 << int(np.ceil(np.log2(2 * n)))
            xc = np.fft.irfft(np.fft.rfft(e, m) * np.conj(np.fft.rfft(s, m)), m)
            vals = np.r_[xc[: max_lag + 1], xc[m - max_lag:]] / n
            key = f"{name}{tag}" if tag != "lin" else f"{name}_lin"
            out[key] = float(np.max(np.abs(vals)))
    return out


def resonance_peaks(e: np.ndarray, y: np.ndarray, fs: float, min_db: float = 10.0, max_peaks: int = 3) -> list[dict[str, float]]:
    """Narrow peaks of the residual PSD that rise ``min_db`` above its running median (unmodelled modes).

    Each peak: frequency [Hz], prominence [dB] above the local median, and residual-to-output power ratio
    at that frequency [dB] (near 0 dB: the simulation misses the output there entirely).
    """
    f, pe = _psd(e, fs)
    _, py = _psd(y, fs)
    if pe.size < 16:
        return []
    lp = 10 * np.log10(pe + 1e-300)
    k = max(5, (pe.size // 20) | 1)
    med = sps.medfilt(lp, k)
    prom = lp - med
    idx, _ = sps.find_peaks(prom, height=min_db)
    idx = idx[np.argsort(prom[idx])[::-1]][:max_peaks]
    return [{"freq_hz": float(f[i]), "prominence_db": float(prom[i]),
             "residual_over_output_db": float(10 * np.log10((pe[i] + 1e-300) / (py[i] + 1e-300)))} for i in idx]


def quantization_step(y: np.ndarray, max_levels: int = 200000) -> dict[str, float]:
    """Detect a lattice in the measured values: the step q such that y/q is (nearly) an integer.

    The candidate step is the smallest clearly non-zero |Δy|; the lattice is confirmed when the values'
    remainders modulo q cluster (Rayleigh test of the phase 2πy/q: ``coherence`` near 1, p-value tiny).
    A continuous (un-quantised or finely quantised) signal gives coherence ≈ 0.
    """
    y = np.asarray(y, dtype=float)
    d = np.abs(np.diff(y))
    d = d[d > 1e-12 * max(np.max(np.abs(y)), 1e-300)]
    if d.size < 10:
        return {"step": 0.0, "coherence": 0.0, "p_value": 1.0, "distinct_levels": int(np.unique(y).size)}
    q = float(np.min(d))
    # ensure the smallest step is typical (a lattice makes many diffs equal to multiples of q)
    ratio = d / q
    on = np.mean(np.abs(ratio - np.round(ratio)) < 0.02)
    ph = 2 * np.pi * (y - y[0]) / q
    coh = float(np.hypot(np.mean(np.cos(ph)), np.mean(np.sin(ph))))
    n = y.size
    p = float(np.exp(-n * coh ** 2))
    levels = int(np.unique(np.round((y - y.min()) / q)).size) if np.ptp(y) / q < max_levels else -1
    return {"step": q, "coherence": coh * float(on), "p_value": p if on > 0.9 else 1.0, "on_lattice": float(on),
            "distinct_levels": levels}


def saturation_rails(y: np.ndarray, ysim: np.ndarray, min_count: int = 5, min_share: float = 0.002,
                     k_rms: float = 2.0) -> dict[str, Any]:
    """Saturation rails of a measured record: the levels where the measuring chain clipped it.

    A side (top or bottom) is a rail when (a) the measured extreme value is taken *exactly* by at least
    ``max(min_count, min_share·N)`` samples (a flat top: an analogue signal, or a quantised one that does not
    clip, reaches its extreme at a few isolated samples) and (b) on those samples the prediction lies beyond
    the extreme by a median of more than ``k_rms`` times the residual RMS of the other samples (the model says
    the signal went further than the instrument could show). Such samples are censored: the measurement only
    says "at least this far"; a prediction clipped to the rails is what the instrument would have shown.

    Returns ``{"lo", "hi"}`` (None where that side has no rail), the sample counts and the median excess.
    """
    y = np.asarray(y, dtype=float)
    s = np.asarray(ysim, dtype=float)
    n = y.size
    out: dict[str, Any] = {"lo": None, "hi": None, "n_lo": 0, "n_hi": 0}
    if n < 8 or not np.all(np.isfinite(s)):
        return out
    need = max(int(min_count), int(np.ceil(min_share * n)))
    sides = {}
    for side, level, sign in (("hi", float(np.max(y)), 1.0), ("lo", float(np.min(y)), -1.0)):
        at = y == level
        if int(at.sum()) >= need:
            sides[side] = (level, sign, at)
    if not sides:
        return out
    at_any = np.zeros(n, dtype=bool)
    for _, _, at in sides.values():
        at_any |= at
    rest = ~at_any
    rms = float(np.sqrt(np.mean((y[rest] - s[rest]) ** 2))) if rest.any() else 0.0
    for side, (level, sign, at) in sides.items():
        excess = float(np.median(sign * (s[at] - level)))
        if excess > k_rms * rms:
            out[side] = level
            out[f"n_{side}"] = int(at.sum())
            out[f"excess_{side}"] = excess
    return out


def clip_to_rails(ysim: np.ndarray, rails: dict[str, Any] | None) -> np.ndarray:
    """The prediction as the saturating instrument would show it (:func:`saturation_rails`)."""
    if not rails or (rails.get("lo") is None and rails.get("hi") is None):
        return ysim
    lo = -np.inf if rails.get("lo") is None else float(rails["lo"])
    hi = np.inf if rails.get("hi") is None else float(rails["hi"])
    return np.clip(ysim, lo, hi)


# ---------------------------------------------------------------------------------------------- hysteresis
def _segments(meta: dict[str, Any], n: int) -> list[dict[str, Any]]:
    segs = meta.get("segments") or []
    out = []
    for s in segs:
        try:
            a, b = int(s["start"]), int(s["stop"])
        except (KeyError, TypeError, ValueError):
            continue
        f = s.get("freq_hz", s.get("frequency_hz", s.get("freq", s.get("f_hz"))))
        if f is None or not (0 <= a < b <= n):
            continue
        out.append({"start": a, "stop": b, "freq_hz": float(f)})
    return out


def _loop_metrics(u: np.ndarray, y: np.ndarray, f: float, fs: float) -> tuple[float, float]:
    """Loop width (max vertical gap between rising and falling branches ÷ output span) and the phase lag
    [deg] of the output's fundamental behind the input's, over the whole periods of a sine segment."""
    n = u.size
    per = fs / f
    nper = int(n // per)
    if nper < 1:
        return float("nan"), float("nan")
    # use the last whole periods (after the start-up transient when there are several)
    use = int(round(max(1, nper - 1 if nper > 2 else nper) * per))
    u = u[-use:]
    y = y[-use:]
    t = np.arange(use) / fs
    c, s = np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)
    A = np.column_stack([np.ones(use), c, s])
    cu, *_ = np.linalg.lstsq(A, u, rcond=None)
    cy, *_ = np.linalg.lstsq(A, y, rcond=None)
    pu = np.arctan2(-cu[2], cu[1])
    py = np.arctan2(-cy[2], cy[1])
    lag = float(np.degrees((pu - py + np.pi) % (2 * np.pi) - np.pi))
    du = np.gradient(u)
    grid = np.linspace(np.percentile(u, 5), np.percentile(u, 95), 41)
    span = float(np.ptp(y)) or 1e-300
    gaps = []
    for sign in (1, -1):
        pass
    up, dn = du > 0, du < 0
    if up.sum() < 3 or dn.sum() < 3:
        return float("nan"), lag
    ou = np.argsort(u[up])
    od = np.argsort(u[dn])
    yu = np.interp(grid, u[up][ou], y[up][ou])
    yd = np.interp(grid, u[dn][od], y[dn][od])
    gaps = np.abs(yu - yd)
    return float(np.max(gaps) / span), lag


def hysteresis_by_segment(u: np.ndarray, y: np.ndarray, ysim: np.ndarray, fs: float, meta: dict[str, Any]) -> list[dict[str, float]]:
    """Loop width (share of span) and phase lag [deg], measured and simulated, for each sine segment listed in
    ``meta['segments']`` (dicts with ``start``, ``stop`` and the frequency ``freq_hz``)."""
    out = []
    for s in _segments(meta, len(u)):
        a, b, f = s["start"], s["stop"], s["freq_hz"]
        if f <= 0:
            continue
        wm, lm = _loop_metrics(u[a:b], y[a:b], f, fs)
        ws, ls = _loop_metrics(u[a:b], ysim[a:b], f, fs)
        out.append({"freq_hz": f, "width_measured": wm, "width_simulated": ws, "lag_deg_measured": lm,
                    "lag_deg_simulated": ls})
    return out


# ---------------------------------------------------------------------------------------------- eq. 2-32
def correlation_tests(e: np.ndarray, u: np.ndarray, max_lag: int = 20, alpha: float = 0.05) -> dict[str, Any]:
    """The five correlation tests of eq. 2-32 via ``sysid.residuals.correlation_tests`` (team poly).

    Until that module exists in the build, a local implementation of the same five tests (eq. 2-33
    normalisation, band ±z_{1−α/2}/√N) is used; the result says which (``impl``).
    """
    try:
        from sysid.residuals import correlation_tests as ct  # type: ignore
        res = ct(np.asarray(e, float), np.asarray(u, float), max_lag=max_lag, alpha=alpha)
        res = dict(res)
        res["impl"] = "sysid.residuals"
        return res
    except ImportError:
        return _correlation_tests_local(e, u, max_lag, alpha)


def _xcorr(x: np.ndarray, y: np.ndarray, max_lag: int, both: bool) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, float) - np.mean(x)
    y = np.asarray(y, float) - np.mean(y)
    n = x.size
    den = np.sqrt(np.sum(x ** 2) * np.sum(y ** 2)) or 1e-300
    m = 1 << int(np.ceil(np.log2(2 * n)))
    xc = np.fft.irfft(np.conj(np.fft.rfft(x, m)) * np.fft.rfft(y, m), m) / den  # φ_xy(τ)=Σx(t)y(t+τ)
    if both:
        lags = np.arange(-max_lag, max_lag + 1)
        vals = np.r_[xc[m - max_lag:], xc[: max_lag + 1]]
    else:
        lags = np.arange(0, max_lag + 1)
        vals = xc[: max_lag + 1]
    return lags, vals


def _correlation_tests_local(e: np.ndarray, u: np.ndarray, max_lag: int, alpha: float) -> dict[str, Any]:
    e = np.asarray(e, float)
    u = np.asarray(u, float)
    n = e.size
    band = float(stats.norm.ppf(1 - alpha / 2) / np.sqrt(n))
    u2 = u ** 2 - np.mean(u ** 2)
    eu = np.r_[e[1:] * u[1:], 0.0]
    defs = [("r_ee", e, e, True, True), ("r_ue", u, e, True, False), ("r_e(eu)", e, eu, False, False),
            ("r_u2'e", u2, e, True, False), ("r_u2'e2", u2, e ** 2, True, False)]
    tests = []
    for name, a, b, both, skip0 in defs:
        lags, vals = _xcorr(a, b, max_lag, both)
        mask = np.abs(vals) > band
        if skip0:
            mask &= lags != 0
        tests.append({"name": name, "passed": not bool(mask.any()), "failing_lags": [int(v) for v in lags[mask]],
                      "values": vals.tolist(), "lags": lags.tolist(), "band": band})
    return {"passed": all(t["passed"] for t in tests), "tests": tests, "impl": "local"}


def tests_summary(ct: dict[str, Any]) -> dict[str, Any]:
    """Compact form kept in the JSON: per test, passed, number of failing lags and the failing lags."""
    return {"passed": bool(ct.get("passed")),
            "tests": [{"name": t["name"], "passed": bool(t["passed"]), "n_failing": len(t.get("failing_lags", [])),
                       "failing_lags": [int(v) for v in t.get("failing_lags", [])][:40],
                       "max_abs": float(np.max(np.abs(t["values"]))) if len(t.get("values", [])) else 0.0,
                       "band": float(np.atleast_1d(t.get("band", 0.0))[0]) if np.ndim(t.get("band", 0.0)) <= 1 else None}
                      for t in ct.get("tests", [])]}


# ---------------------------------------------------------------------------------------------- everything
def analyse(u: np.ndarray, y: np.ndarray, ysim: np.ndarray, fs: float, meta: dict[str, Any] | None = None,
            max_lag: int = 20, max_echo_s: float | None = None) -> dict[str, Any]:
    """All residual numbers for one record (see the module docstring)."""
    meta = meta or {}
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    ysim = np.asarray(ysim, float)
    e = y - ysim
    ysd = float(np.std(y)) or 1e-300
    out: dict[str, Any] = {"n": int(e.size), "fs": float(fs), "rms": float(np.sqrt(np.mean(e ** 2))),
                           "nrmse": float(np.sqrt(np.mean(e ** 2)) / ysd), "mean": float(np.mean(e))}
    out["trend"] = trend(e, fs)
    out["step_drift"] = step_drift(u, e, fs)
    out["delay"] = delay_estimate(y, ysim, fs, max_shift_s=max(64, e.size // 50) / fs)
    out["io_delay_s"] = io_delay(u, y, fs)
    out["io_delay_sim_s"] = io_delay(u, ysim, fs)
    out["echo"] = lag_regression(e, ysim, fs, max_lag_s=max_echo_s, min_lag=_min_echo_lag(ysim, fs))
    out["input_lag"] = lag_regression(e, u, fs, max_lag_s=max_lag / fs * 5)
    out["bands"] = band_powers(e, u, y, fs)
    out["products"] = product_bands(e, u, fs)
    out["early_input"] = early_input_correlation(e, u, ysim, fs)
    segs = [sg for sg in _segments(meta, e.size) if sg["freq_hz"] * (sg["stop"] - sg["start"]) / fs >= 2]
    if segs:  # sine segments: harmonics per segment, odd and even powers summed over segments
        hs = [harmonics(e[sg["start"]:sg["stop"]], u[sg["start"]:sg["stop"]], fs) for sg in segs]
        odd = sum(sum(a ** 2 for i, a in enumerate(h["amplitudes"], 1) if i % 2 == 1 and i > 1) for h in hs)
        even = sum(sum(a ** 2 for i, a in enumerate(h["amplitudes"], 1) if i % 2 == 0) for h in hs)
        out["harmonics"] = {"f0_hz": [h["f0_hz"] for h in hs], "sine_share": 1.0, "per_segment": hs,
                            "odd_over_even_db": float(10 * np.log10((odd + 1e-300) / (even + 1e-300)))}
    else:
        out["harmonics"] = harmonics(e, u, fs)
    period = (meta.get("period_samples") or (meta.get("multisine") or {}).get("period_samples")
              or (meta.get("excitation") or {}).get("period_samples"))
    out["lines"] = odd_even_lines(u, y, e, fs, period=int(period) if period else None)
    out["nonlinear"] = nonlinear_correlation(e, u, ysim, max_lag=max_lag)
    out["resonances"] = resonance_peaks(e, y, fs)
    out["quantization"] = quantization_step(y)
    out["hysteresis"] = hysteresis_by_segment(u, y, ysim, fs, meta)
    out["effective_samples"] = effective_samples(e)
    ct = correlation_tests(e, u, max_lag=max_lag)
    out["tests"] = tests_summary(ct)
    out["_tests_full"] = ct
    return out


def _min_echo_lag(ysim: np.ndarray, fs: float) -> int:
    """Smallest lag at which the simulated output's autocorrelation envelope has fallen below 0.3: an echo is
    only separable from a gain or shape error beyond the signal's own correlation length."""
    x = np.asarray(ysim, float) - np.mean(ysim)
    n = x.size
    if n < 16 or not np.any(x):
        return 1
    m = 1 << int(np.ceil(np.log2(2 * n)))
    ac = np.fft.irfft(np.abs(np.fft.rfft(x, m)) ** 2, m)[: n // 2]
    env = np.abs(sps.hilbert(ac))
    env = env / (env[0] or 1e-300)
    below = np.flatnonzero(env < 0.3)
    return int(below[0]) if below.size else 1
