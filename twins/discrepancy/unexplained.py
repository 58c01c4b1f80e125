"""Unexplained residual: the data lie outside what the twin can represent.

After the best extension the validation residual e is compared with the measurement-noise level σ², measured
from the data themselves (never from the twin's noise parameter):

- **hold segments**: stretches where u is constant (|Δu| ≤ 10⁻⁹·span) for ≥ 40 samples; the second half of
  each hold (after the settling of the modes and the sensor) is detrended linearly (slow creep/drift) and its
  variance taken; the median over the holds;
- **high-frequency floor**: the median periodogram level of y in the top 10 % of the band (f > 0.9·fs/2) over
  ln 2, times the band (white noise has the flat one-sided density 2σ²/fs; a periodogram bin of it is that
  density times an exponential variable, whose median is ln 2 of its mean);
- **second differences**: σ² ≈ (1.4826·MAD(Δ²y))²/6 (Δ² of white noise has variance 6σ²; the median ignores
  the few samples where a step or an edge dominates; none on a quantised reading whose Δ² are mostly 0).

Each estimate can only be raised by signal content leaking into it, so the smallest is used. The excess ratio R =
mean(e²)/σ² (validation, after the extension). These floors see white noise; coloured noise lifts R with a right
model (AR(1) of pole ρ: up to (1 + ρ)/(1 − ρ), 19 at 0.9). So when R > :data:`EXCESS_LIMIT` the residual must also
be more than coloured noise (:func:`structure`, level :data:`STRUCTURE_LEVEL`): it depends on the drive or the
prediction by generalised least squares (a model error is a function of the input history; noise is not), or it
holds a periodic line (hum). Then the verdict is ``unexplained``: "outside the model class: X % of residual power
unexplained" with X = 100·(1 − σ²/mean(e²)), and its signature: where the residual's power lies in frequency (share
below f_low = fs/200, between, and above f_high = fs/10; the peak of its Welch spectrum) and its correlation with u,
|u|, sign(u̇) and the slow trend (which tells a dead zone, a backlash, a resonance and a drift apart in words). The
limit 9 (residual RMS 3× the noise) and its margins: docs/diagnosis.md.

:func:`generic_residual_model` tests what is left for structure no catalog entry explains: a generic
linear-in-parameters residual model (FIR of u, (u²)′, (u³)′ and a trend) fitted on the estimation residual and
scored on the validation residual with the diagnosis' F-test.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal as sps

from sysid.data.record import Record
from sysid.evaluation.residuals import ar_prewhiten, line_test, periodicity_test

from .features import effective_samples
from .prediction import significance

__all__ = [
    "EXCESS_LIMIT",
    "STRUCTURE_LEVEL",
    "noise_level",
    "records_noise",
    "excess_ratio",
    "outside",
    "structure",
    "judge",
    "generic_residual_model",
]

#: residual power / noise power above which the residual is "far above the noise"
EXCESS_LIMIT = 9.0
#: level of :func:`structure`: a residual far above the noise floor is outside the model class only if it is
#: more than coloured noise at this level
STRUCTURE_LEVEL = 0.01
#: lags of u and ŷ in :func:`structure` and the largest order of its prewhitening AR model
STRUCTURE_LAGS = 10
STRUCTURE_AR_ORDER = 10


def _holds(u: np.ndarray, min_len: int = 40) -> list[tuple[int, int]]:
    span = float(np.ptp(u)) or 1.0
    still = np.abs(np.diff(u)) <= 1e-9 * span
    out, start = [], None
    for i, s in enumerate(np.append(still, False)):
        if s and start is None:
            start = i
        elif not s and start is not None:
            if i + 1 - start >= min_len:
                out.append((start, i + 1))
            start = None
    return out


def noise_level(u: np.ndarray, y: np.ndarray, fs: float) -> dict[str, Any]:
    """Noise variance σ² of ``y`` estimated from the data (module docstring); returns the estimates and the
    one used."""
    u = np.asarray(u, float).ravel()
    y = np.asarray(y, float).ravel()
    est: dict[str, float] = {}
    hv = []
    for a, b in _holds(u):
        seg = y[a + (b - a) // 2 : b]
        if seg.size >= 20:
            t = np.arange(seg.size)
            c = np.polyfit(t, seg, 1)
            hv.append(float(np.var(seg - np.polyval(c, t))))
    if hv:
        est["holds"] = float(np.median(hv))
    if y.size >= 256:
        f, p = sps.periodogram(y - np.mean(y), fs=fs, detrend="linear")
        band = f > 0.9 * fs / 2
        if np.count_nonzero(band) >= 8:
            est["hf_floor"] = float(np.median(p[band]) / math.log(2.0) * fs / 2)
    if y.size >= 16:
        d2 = np.diff(y, 2)
        mad = float(np.median(np.abs(d2 - np.median(d2))))
        # a reading on a grid (a quantiser finer than its noise is not): when most Δ² are 0, the MAD is 0 up to
        # rounding (1e-31 of the span) and no estimate of σ² — counted as 0 and left out, as an exact 0 is
        est["second_diff"] = (1.4826 * mad) ** 2 / 6.0 if mad > 1e-9 * float(np.ptp(y)) else 0.0
    pos = {k: v for k, v in est.items() if v > 0 and math.isfinite(v)}
    if pos:
        src = min(pos, key=lambda k: pos[k])
        return {"sigma2": pos[src], "source": src, "estimates": est}
    # exactly repeatable (noise-free, e.g. quantised and constant) data: a tiny floor from the value spacing
    return {"sigma2": 0.0, "source": "none", "estimates": est}


def records_noise(est: Record, val: Record) -> dict[str, Any]:
    """:func:`noise_level` of the estimation and validation records together: the level the verdict compares the
    validation residual with."""
    u = np.concatenate([np.asarray(est.u, float), np.asarray(val.u, float)])
    return noise_level(u, np.concatenate([est.output, val.output]), est.fs)


def excess_ratio(p_e: float, s2: float) -> float:
    """R = mean(e²)/σ² (inf for a residual over noise-free data, 1 for no residual at all)."""
    return p_e / s2 if s2 > 0 else (float("inf") if p_e > 0 else 1.0)


def outside(e: np.ndarray, noise: dict[str, Any]) -> bool:
    """The residual ``e`` lies far above the noise level ``noise`` (:func:`noise_level`), R > :data:`EXCESS_LIMIT`
    (the pairs' test of a residual above the noise; the verdict also asks :func:`structure`, in :func:`judge`)."""
    return bool(excess_ratio(float(np.mean(e * e)), float(noise["sigma2"])) > EXCESS_LIMIT)


def judge(
    u: np.ndarray, y: np.ndarray, yhat: np.ndarray, fs: float, skip: int = 0, noise: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Compare the residual y − ŷ with the noise level; ``outside`` True when it is far above it and more than
    coloured noise (:func:`structure`, tested only then)."""
    u = np.asarray(u, float).ravel()[skip:]
    y = np.asarray(y, float).ravel()[skip:]
    yh = np.asarray(yhat, float).ravel()[skip:]
    e = y - yh
    nl = noise or noise_level(u, y, fs)
    s2 = float(nl["sigma2"])
    p_e = float(np.mean(e * e))
    ratio = excess_ratio(p_e, s2)
    frac = max(0.0, 1.0 - s2 / p_e) if p_e > 0 else 0.0
    st = structure(u, yh, e) if ratio > EXCESS_LIMIT else None
    structured = st is None or st["p_value"] < STRUCTURE_LEVEL or st["p_line"] < STRUCTURE_LEVEL
    out: dict[str, Any] = {
        "noise_var": s2,
        "noise_source": nl["source"],
        "noise_estimates": nl["estimates"],
        "residual_var": p_e,
        "excess_ratio": ratio,
        "unexplained_fraction": frac,
        "limit": EXCESS_LIMIT,
        "outside": bool(ratio > EXCESS_LIMIT and structured),
        "structure": st,
    }
    sig = signature(u, e, fs)
    out["signature"] = sig
    out["text"] = (
        f"outside the model class: {100 * frac:.0f} % of residual power unexplained (residual RMS "
        f"{math.sqrt(p_e):.3g}, noise RMS {math.sqrt(s2):.3g} from {nl['source'].replace('_', ' ')}; "
        f"{ratio:.3g}× the noise power); its signature: {sig['text']}"
    )
    if st is not None and not structured:
        out["text"] = (
            f"residual {ratio:.3g}× the noise floor's power ({nl['source'].replace('_', ' ')}), but no more than "
            f"coloured noise: prewhitened by an AR({st['ar_order']}) model it depends neither on the drive nor on "
            f"the prediction (p {st['p_dependence']:.2g}) and has no periodic line (p {st['p_periodic']:.2g}; "
            f"against the smooth spectrum around it, p {st['p_line']:.2g})"
        )
    return out


def signature(u: np.ndarray, e: np.ndarray, fs: float) -> dict[str, Any]:
    """Residual spectrum (band shares, peak) and correlations with u, |u|, sign(u̇) and a linear trend."""
    n = e.size
    nper = int(min(n, max(64, 1 << int(math.log2(max(n // 8, 2))))))
    f, p = sps.welch(e - np.mean(e), fs=fs, nperseg=nper)
    tot = float(np.sum(p)) or 1.0
    f_lo, f_hi = fs / 200.0, fs / 10.0
    low = float(np.sum(p[f <= f_lo]) / tot)
    high = float(np.sum(p[f >= f_hi]) / tot)
    peak = float(f[int(np.argmax(p[1:])) + 1]) if p.size > 1 else 0.0

    def corr(a, b):
        a = a - np.mean(a)
        b = b - np.mean(b)
        d = math.sqrt(float(a @ a) * float(b @ b))
        return float(a @ b / d) if d > 0 else 0.0

    du = np.gradient(u)
    cu = {
        "u": corr(e, u),
        "|u|": corr(e, np.abs(u)),
        "sign(du/dt)": corr(e, np.sign(du)),
        "trend": corr(e, np.arange(n, dtype=float)),
    }
    mean_share = float(np.mean(e) ** 2 / max(np.mean(e * e), 1e-300))
    strongest = max(cu, key=lambda k: abs(cu[k]))
    text = (
        f"{100 * low:.0f} % of its power below {f_lo:.3g} Hz, {100 * high:.0f} % above {f_hi:.3g} Hz, spectral "
        f"peak at {peak:.4g} Hz; correlation with u {cu['u']:+.2f}, |u| {cu['|u|']:+.2f}, "
        f"sign(du/dt) {cu['sign(du/dt)']:+.2f}, time {cu['trend']:+.2f} (strongest: {strongest}); "
        f"mean {100 * mean_share:.0f} % of its power"
    )
    return {"band_low": low, "band_high": high, "peak_hz": peak, "corr": cu, "mean_share": mean_share, "text": text}


def lagged_powers(z: np.ndarray, lags: int) -> np.ndarray:
    """Columns z, z² − 1, z³ − 3z (Hermite polynomials of a standardised signal: near-orthogonal for Gaussian z),
    each delayed by 0 … ``lags`` samples (zeros before the start)."""
    cols = []
    for x in (z, z**2 - 1.0, z**3 - 3 * z):
        for k in range(lags + 1):
            cols.append(np.r_[np.zeros(k), x[: x.size - k]])
    return np.column_stack(cols)


def structure(u: np.ndarray, yhat: np.ndarray, e: np.ndarray, lags: int = STRUCTURE_LAGS) -> dict[str, Any]:
    """Is the residual ``e`` more than noise? Two tests valid for coloured noise (module docstring):

    - **dependence**: e regressed on the lagged powers (:func:`lagged_powers`) of u and of the prediction ŷ, ŷ·t
      and t by feasible generalised least squares: both sides filtered by the AR polynomial (order by BIC ≤ 10)
      of the ordinary least-squares residual of that regression; F-test of the regression;
    - **periodicity**: Fisher's g on e prewhitened by its own AR model
      (:func:`sysid.evaluation.residuals.periodicity_test`);
    - **a line** against the smooth spectrum around it: Thomson's harmonic F-test on e itself
      (:func:`sysid.evaluation.residuals.line_test`, ``p_line``). An AR model fitted to e absorbs a strong line
      (two poles on the unit circle predict a sinusoid), which leaves Fisher's g blind to it: of 20 drawn lines
      3–5× the noise RMS it found 3–5, the line test 20 (diagnosis benchmark seeds 143 and 413, a mains hum at
      R 12 and 26, ended ``none``).

    ``p_value``: the smaller p of the first two, Bonferroni-doubled; the residual is structured when it or
    ``p_line`` is below the level (a false-alarm rate of at most twice the level: on AR(1) noise, ρ 0–0.97, 600–
    50 000 samples, the line test alone rejected 24 of 2560 draws at 0.01). Noise independent of the drive gives
    uniform p."""
    u = np.asarray(u, float).ravel()
    yh = np.asarray(yhat, float).ravel()
    e = np.asarray(e, float).ravel()
    n = e.size
    if n < 4 * (6 * (lags + 1) + 3) + STRUCTURE_AR_ORDER + lags:  # too short to test: R alone decides
        return {"p_value": 0.0, "p_dependence": 0.0, "p_periodic": 1.0, "p_line": 1.0, "ar_order": 0, "explained": 0.0}
    eps, _ = ar_prewhiten(e, STRUCTURE_AR_ORDER)
    t = np.linspace(-1.0, 1.0, n)
    zu = (u - u.mean()) / (float(np.std(u)) or 1.0)
    zy = (yh - yh.mean()) / (float(np.std(yh)) or 1.0)
    Z = np.column_stack([lagged_powers(zu, lags), lagged_powers(zy, lags), zy * t, t])
    # feasible GLS (Cochrane & Orcutt 1949): the noise's AR model is fitted to what an ordinary least-squares fit
    # of the regression leaves, not to e itself — an AR model of e absorbs a deterministic narrow-band residual
    # (the harmonics of a sines record: ten lags predict five lines exactly) and the test's power with it
    Z1 = np.column_stack([np.ones(n), Z])[lags:]
    r0 = e[lags:] - Z1 @ np.linalg.lstsq(Z1, e[lags:], rcond=None)[0]
    _, a = ar_prewhiten(r0, STRUCTURE_AR_ORDER)
    filt = np.r_[1.0, -a]
    cut = a.size + lags
    et = sps.lfilter(filt, [1.0], e - e.mean())[cut:]
    Zt = np.column_stack([np.ones(et.size), sps.lfilter(filt, [1.0], Z, axis=0)[cut:]])
    c = np.linalg.lstsq(Zt, et, rcond=None)[0]
    r = et - Zt @ c
    p_dep = significance(float(et @ et), float(r @ r), float(et.size), Zt.shape[1])
    p_per = float(periodicity_test(eps)["p_value"])
    return {
        "p_value": float(min(1.0, 2.0 * min(p_dep, p_per))),
        "p_dependence": float(p_dep),
        "p_periodic": p_per,
        "p_line": float(line_test(e)["p_value"]),
        "ar_order": int(a.size),
        "explained": float(1.0 - (r @ r) / (et @ et)) if float(et @ et) > 0 else 0.0,
    }


def generic_residual_model(
    est: Record, val: Record, e_est: np.ndarray, e_val: np.ndarray, lags: int, skip: int
) -> dict[str, Any]:
    """Structure no catalog entry explains: a FIR model of the residual on u, (u²)′, (u³)′ (lags 0…L) and a
    trend, fitted on the estimation residual and scored on the validation residual (relative SSE, F-test)."""

    def design(rec: Record) -> np.ndarray:
        u = np.asarray(rec.u, float)
        z = (u - float(np.mean(est.u))) / (float(np.std(est.u)) or 1.0)
        return np.column_stack([np.ones_like(z), np.linspace(-1, 1, z.size), lagged_powers(z, lags)])

    A = design(est)[skip:]
    # ridge-regularised least squares: lagged copies of a slow input are nearly collinear, and an unregularised
    # fit would extrapolate wildly to the validation record
    G = A.T @ A
    lam = 1e-4 * float(np.mean(np.diag(G))) or 1e-12
    c = np.linalg.solve(G + lam * np.eye(G.shape[0]), A.T @ e_est[skip:])
    pv = design(val)[skip:] @ c
    ev_ = e_val[skip:]
    sse0 = float(ev_ @ ev_)
    sse1 = float((ev_ - pv) @ (ev_ - pv))
    n_eff = effective_samples(ev_ - pv)
    p = significance(sse0, sse1, n_eff, A.shape[1])
    return {"nrmse_ratio": math.sqrt(sse1 / sse0) if sse0 > 0 else 1.0, "p_value": p, "n_terms": int(A.shape[1])}
