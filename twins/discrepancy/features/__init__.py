"""Residual analysis of a twin's free-run simulation against measured data: :func:`analyse` and its features.

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
- :func:`correlation_tests` — the five tests of eq. 2-32, with the failing lags (``sysid.evaluation.residuals``, the
  one implementation; :func:`tests_summary` is its compact form for JSON).

The time-domain features live in :mod:`.timing`, the spectral ones in :mod:`.spectra`, the value lattice,
saturation rails and hysteresis loops in :mod:`.levels`; this module combines them.
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
