"""Residual analysis of a twin's free-run simulation against measured data: :func:`analyse` and its features.

Plain arrays and an explicit ``fs`` [Hz] in, dicts of floats out, in the manner of ``scipy.signal``. The
residual is ``e = y - y_sim``, eq. 2-30's ξ(t) = y(t) − ŷ(t). Each feature and the effect it points to:

- :func:`trend`, :func:`step_drift` — slow drift, and drift after steps regressed on ``Δu·log10(t)`` (creep's
  logarithmic law, physics notes A.5): thermal drift, creep, offsets;
- :func:`lag_regression` — the residual on a delayed copy of the output or input: a peak at τ > 0 is an echo
  (notes B.8), a derivative-shaped peak at 0 a delay; :func:`delay_estimate` — the sub-sample alignment;
- :func:`early_input_correlation` — residual–input correlation before the first arrival: crosstalk;
- :func:`band_powers`, :func:`product_bands`, :func:`harmonics`, :func:`odd_even_lines` — power in and out of
  the excited band, at even-order products of a narrow band, at a sine's harmonics, on a multisine's detection
  lines (Pintelon & Schoukens): odd versus even distortion;
- :func:`nonlinear_correlation` — correlation with the parts of u², u³, ŷ², ŷ³ orthogonal to the linear terms;
- :func:`resonance_peaks` — narrow peaks of the residual spectrum (unmodelled resonances);
- :func:`quantization_step`, :func:`saturation_rails` — a lattice in the measured values; flat tops where the
  measurement saturated (censored samples, not model errors);
- :func:`hysteresis_by_segment` — loop width and phase lag per sine segment, measured versus simulated;
- :func:`correlation_tests` — the five tests of eq. 2-32 (:mod:`sysid.evaluation.residuals`).

Time-domain features live in :mod:`.timing`, spectral ones in :mod:`.spectra`, levels and loops in
:mod:`.levels`; this module combines them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import signal as sps

from sysid.evaluation.residuals import correlation_tests, tests_summary

from .levels import _segments, clip_to_rails, hysteresis_by_segment, quantization_step, saturation_rails
from .spectra import (
    band_powers,
    excited_band,
    harmonics,
    nonlinear_correlation,
    odd_even_lines,
    product_bands,
    resonance_peaks,
)
from .timing import (
    delay_candidates,
    delay_estimate,
    early_input_correlation,
    effective_samples,
    io_delay,
    lag_regression,
    step_drift,
    trend,
)

__all__ = [
    "trend",
    "step_drift",
    "lag_regression",
    "delay_estimate",
    "band_powers",
    "harmonics",
    "odd_even_lines",
    "nonlinear_correlation",
    "resonance_peaks",
    "quantization_step",
    "hysteresis_by_segment",
    "correlation_tests",
    "effective_samples",
    "analyse",
    "saturation_rails",
    "clip_to_rails",
    "early_input_correlation",
    "product_bands",
    "delay_candidates",
    "io_delay",
    "excited_band",
    "tests_summary",
]


def analyse(
    u: np.ndarray,
    y: np.ndarray,
    ysim: np.ndarray,
    fs: float,
    meta: dict[str, Any] | None = None,
    max_lag: int = 20,
    max_echo_s: float | None = None,
) -> dict[str, Any]:
    """All residual numbers for one record (see the module docstring)."""
    meta = meta or {}
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    ysim = np.asarray(ysim, float)
    e = y - ysim
    ysd = float(np.std(y)) or 1e-300
    out: dict[str, Any] = {
        "n": int(e.size),
        "fs": float(fs),
        "rms": float(np.sqrt(np.mean(e**2))),
        "nrmse": float(np.sqrt(np.mean(e**2)) / ysd),
        "mean": float(np.mean(e)),
    }
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
        hs = [harmonics(e[sg["start"] : sg["stop"]], u[sg["start"] : sg["stop"]], fs) for sg in segs]
        odd = sum(sum(a**2 for i, a in enumerate(h["amplitudes"], 1) if i % 2 == 1 and i > 1) for h in hs)
        even = sum(sum(a**2 for i, a in enumerate(h["amplitudes"], 1) if i % 2 == 0) for h in hs)
        out["harmonics"] = {
            "f0_hz": [h["f0_hz"] for h in hs],
            "sine_share": 1.0,
            "per_segment": hs,
            "odd_over_even_db": float(10 * np.log10((odd + 1e-300) / (even + 1e-300))),
        }
    else:
        out["harmonics"] = harmonics(e, u, fs)
    period = (
        meta.get("period_samples")
        or (meta.get("multisine") or {}).get("period_samples")
        or (meta.get("excitation") or {}).get("period_samples")
    )
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
