"""A named cause whose characteristic frequency lies above the records' Nyquist frequency.

A first-order low-pass of corner f_c acts within the band |f| < f_N ≪ f_c as 1 − j·f/f_c: a lag of 1/(2π·f_c), which
a delay, a slower drive or a filtered sensor give alike; a mode above the band acts as its static share, a
feed-through of the drive that crosstalk gives alike. The data then say that such a term fits, not which one: its
corner or its resonance is not seen. On the diagnosis benchmark's 500 stored cases (docs/diagnosis-benchmark.md),
6 of the 23 named causes whose frequency (a corner, a bandwidth, a second mode) lay above the Nyquist frequency were
right, and 11 of the 32 wrong names stated with confidence ≥ ½ were such causes. Such a cause is marked
(``above_nyquist``: its frequency and the Nyquist frequency, in Hz) and its confidence capped at
:data:`twins.discrepancy.confidence.BAND_CAP` (:func:`.confidence.calibrate_causes`).

A twin may say which frequency an effect stands for (``effect_frequency_hz(effect, params)``: the cantilever's
second mode at mode_ratio·f₁); otherwise it is the largest of the effect's parameters in Hz.
"""

from __future__ import annotations

import math
from typing import Any

from twins.paramfields import param_info

__all__ = ["characteristic_hz", "above_band_hz", "mark_above_nyquist"]


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


def mark_above_nyquist(causes: list[dict[str, Any]], twin: Any, fs: float) -> None:
    """Mark each catalog cause of ``causes`` whose frequency lies above ``fs``/2 (module docstring), in place."""
    nyquist = 0.5 * float(fs)
    for c in causes:
        if c["effect"] == "unexplained" or c["effect"] not in getattr(twin, "EFFECTS", {}):
            continue
        f = above_band_hz(twin, c["effect"], c.get("params", {}), fs)
        if f is None:
            continue
        c["above_nyquist"] = {"hz": f, "nyquist_hz": nyquist}
        c["evidence"] = (
            c.get("evidence", "")
            + f"; its frequency, {f:.4g} Hz, lies above the records' Nyquist frequency ({nyquist:.4g} Hz): within "
            "the band it acts as its low-frequency form (a lag, a feed-through), which other mechanisms share"
        )
