"""A named cause whose characteristic frequency lies outside the records' band: above the Nyquist frequency, pinned at
the top of its range, or a time constant longer than the records.

A first-order low-pass of corner f_c acts within the band |f| < f_N ≪ f_c as 1 − j·f/f_c: a lag of 1/(2π·f_c), which
a delay, a slower drive or a filtered sensor give alike; a mode above the band acts as its static share, a
feed-through of the drive that crosstalk gives alike. The data then say that such a term fits, not which one. On the
diagnosis benchmark's 500 cases (docs/diagnosis-benchmark.md) 6 of the 23 causes named above the Nyquist frequency
were right. Such a cause is marked ``above_nyquist`` (its frequency and the Nyquist frequency, in Hz). A frequency
fitted at the top of its documented range (a corner, the second mode's ratio to the first) is the same case within
the band — the fit would place it higher (case 399: a drive feed-through named `second_mode` at the ratio's bound,
7.0 kHz under a 13.8 kHz Nyquist frequency, at 0.83) — marked ``pinned_frequency`` (frequency, parameter, bound).
A twin may say which frequency an effect stands for (``effect_frequency_hz(effect, params)``: the cantilever's
second mode at mode_ratio·f₁); otherwise it is the largest of the effect's parameters in Hz.

At the low end, a stationary effect with a memory (catalog keys ``tau`` / ``tau_min``: rate-dependent hysteresis's
rate envelope, the fastest element of a creep spectrum) starts each record from rest and settles as 1 − e^(−t/τ).
With τ longer than the records it never settles: within them it is a change over time (ρ(t) ≈ t/τ·mean|v̇|, a
hysteretic slope growing through the record), which a drifting gain gives alike. On the benchmark the four causes so
fitted were wrong, two stated ≥ ½ (cases 141: a sagging sensor gain; 358). Marked ``beyond_record`` (τ and the
records' duration, in s); a ``time_varying`` effect (a drift) is exempt. Every mark caps the confidence at
:data:`twins.discrepancy.confidence.BAND_CAP` (:func:`.confidence.calibrate_causes`).
"""

from __future__ import annotations

import math
from typing import Any

from twins.paramfields import param_info

from .ranges import bound_side

__all__ = [
    "characteristic_hz",
    "above_band_hz",
    "pinned_hz",
    "memory_s",
    "mark_outside_band",
]


def characteristic_hz(twin: Any, effect: str, params: dict[str, float]) -> float | None:
    """The frequency [Hz] effect ``effect`` of ``twin`` stands for with its fitted ``params``, or None."""
    hook = getattr(twin, "effect_frequency_hz", None)
    if callable(hook):
        f = hook(effect, params)
        if f is not None:
            return float(f)
    info = param_info(type(twin.params))
    hz = [float(v) for k, v in params.items() if k in info and info[k].unit == "Hz" and math.isfinite(float(v))]
    return max(hz) if hz else None


def above_band_hz(twin: Any, effect: str, params: dict[str, float], fs: float) -> float | None:
    """The frequency [Hz] of ``effect`` with ``params`` (:func:`characteristic_hz`) when it lies above the Nyquist
    frequency ``fs``/2, else None."""
    f = characteristic_hz(twin, effect, params)
    return f if f is not None and f > 0.5 * float(fs) else None


def pinned_hz(twin: Any, effect: str, params: dict[str, float]) -> dict[str, Any] | None:
    """``{"hz", "param", "bound"}`` when a parameter of ``params`` that raises the frequency of ``effect``
    (:func:`characteristic_hz`) lies at the top of its documented range (:func:`.ranges.bound_side`), else None."""
    f = characteristic_hz(twin, effect, params)
    if f is None or not f > 0:
        return None
    info = param_info(type(twin.params))
    for k, v in params.items():
        rng = info[k].range if k in info else None
        if rng is None or rng[0] is None or rng[1] is None or not float(rng[1]) > float(rng[0]):
            continue
        if bound_side(float(v), float(rng[0]), float(rng[1])) != "upper":
            continue
        higher = characteristic_hz(twin, effect, {**params, k: float(v) * 1.01 + 1e-12})
        if higher is not None and higher > f:
            return {"hz": f, "param": k, "bound": float(rng[1])}
    return None


#: catalog keys of an effect's time constant (:class:`twins.base.EffectSpec` ``params``): one τ, or the fastest
#: of a spectrum (creep's τ_1; its elements are τ_1·10^(i−1), all slower)
_TIME_CONSTANT_KEYS = ("tau", "tau_min")


def memory_s(twin: Any, effect: str, params: dict[str, float]) -> float | None:
    """The time constant [s] the stationary effect ``effect`` of ``twin`` settles with, from its fitted ``params``
    (module docstring), or None: no such key, or an effect whose law changes over the record (``time_varying``)."""
    spec = getattr(twin, "EFFECTS", {}).get(effect)
    if spec is None or spec.time_varying:
        return None
    taus = [float(params[f]) for k, f in spec.params.items() if k in _TIME_CONSTANT_KEYS and f in params]
    taus = [t for t in taus if math.isfinite(t)]
    return max(taus) if taus else None


def mark_outside_band(causes: list[dict[str, Any]], twin: Any, fs: float, duration_s: float) -> None:
    """Mark each catalog cause of ``causes`` outside the band (module docstring), in place: ``above_nyquist`` when its
    frequency lies above ``fs``/2 (the larger sampling rate), else ``pinned_frequency`` when it is fitted at the top
    of its range, and ``beyond_record`` when its time constant exceeds ``duration_s`` (the longer record)."""
    nyquist = 0.5 * float(fs)
    for c in causes:
        if c["effect"] == "unexplained" or c["effect"] not in getattr(twin, "EFFECTS", {}):
            continue
        params = c.get("params", {})
        f = above_band_hz(twin, c["effect"], params, fs)
        pinned = pinned_hz(twin, c["effect"], params) if f is None else None
        tau = memory_s(twin, c["effect"], params)
        if f is not None:
            _mark(
                c,
                "above_nyquist",
                {"hz": f, "nyquist_hz": nyquist},
                f"its frequency, {f:.4g} Hz, lies above the records' Nyquist frequency ({nyquist:.4g} Hz): within the "
                "band it acts as its low-frequency form (a lag, a feed-through), which other mechanisms share",
            )
        elif pinned is not None:
            _mark(
                c,
                "pinned_frequency",
                pinned,
                f"its frequency, {pinned['hz']:.4g} Hz, is fitted with {pinned['param']} at the top of its range "
                f"({pinned['bound']:.4g}): the fit would place it higher, its corner or resonance is not found in the "
                "data",
            )
        if tau is not None and tau > float(duration_s):
            _mark(
                c,
                "beyond_record",
                {"tau_s": tau, "record_s": float(duration_s)},
                f"its time constant, {tau:.4g} s, is longer than the records ({float(duration_s):.4g} s): it never "
                "settles within them and acts as a change over the record, which a drifting gain or reading gives "
                "alike",
            )


def _mark(cause: dict[str, Any], key: str, value: Any, why: str) -> None:
    cause[key] = value
    cause["evidence"] = cause.get("evidence", "") + "; " + why
