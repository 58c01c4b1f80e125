"""Which parameters of a twin a diagnosis fits, and where it starts looking for their values.

Numeric parameters with a documented range are fitted (integers are structural and kept), list-valued ones
(a model variant, a fluid) are scanned value by value; the residual features suggest starting values (echo
delays and amplitudes, timing shifts, the path lengths an echo delay implies).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from twins.base import Twin, param_info

from . import evidence as ev

__all__ = [
    "numeric_fields",
    "choice_fields",
    "int_fields",
    "effect_fields",
    "grid",
    "guesses",
    "echo_path_guesses",
    "core_for",
    "quant_params",
    "fmt_params",
]


def numeric_fields(twin: Twin, fields: Iterable[str]) -> list[str]:
    info = param_info(type(twin.params))
    out = []
    for f in fields:
        if f not in info or f in out:
            continue
        v = getattr(twin.params, f)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        lo, hi = info[f].range
        if lo is None or hi is None or not (float(hi) > float(lo)):
            continue
        out.append(f)
    return out


def choice_fields(twin: Twin, fields: Iterable[str]) -> list[str]:
    """Effect parameters that take one of a list of values (e.g. a fluid name): scanned, never least-squares fitted."""
    info = param_info(type(twin.params))
    return [f for f in fields if f in info and info[f].choices]


def int_fields(twin: Twin, fields: Iterable[str]) -> list[str]:
    return [
        f
        for f in fields
        if isinstance(getattr(twin.params, f, None), int) and not isinstance(getattr(twin.params, f, None), bool)
    ]


def grid(lo: float, hi: float, n: int, is_int: bool) -> np.ndarray:
    if lo > 0 and hi / lo > 30:
        g = np.geomspace(lo, hi, n)
    else:
        g = np.linspace(lo, hi, n)
    if is_int:
        g = np.unique(np.round(g))
    return g


def guesses(field: str, unit: str, a: dict[str, Any], twin: Twin, current: float) -> list[float]:
    """Values of an effect parameter that the residual features suggest (delays, path lengths, amplitudes)."""
    u = (unit or "").strip().lower()
    name = field.lower()
    sh = a["delay"]["shift_s"]
    tau = a["echo"].get("lag_s", float("nan"))
    coef = a["echo"].get("coef", 0.0)
    out: list[float] = []
    if u in ("s", "sec", "seconds"):
        out += [sh, abs(sh), current + sh]
        if math.isfinite(tau):
            out += [tau]
    elif u in ("us", "µs"):
        out += [sh * 1e6, current + sh * 1e6] + ([tau * 1e6] if math.isfinite(tau) else [])
    elif u in ("ms",):
        out += [sh * 1e3, current + sh * 1e3] + ([tau * 1e3] if math.isfinite(tau) else [])
    elif u in ("samples", "sample"):
        out += [a["delay"]["shift_samples"], current + a["delay"]["shift_samples"]]
        if math.isfinite(tau):
            out += [tau * a["fs"]]
    elif u == "m" or u == "mm":
        c = ev.sound_speed(twin)
        k = 1e3 if u == "mm" else 1.0
        if c:
            out += [k * c * sh, current + k * c * sh]
            out += echo_path_guesses(unit, a, twin)
    if any(w in name for w in ("amp", "gain", "coef", "reflect", "level", "scale")) and u in ("", "1", "-", "ratio"):
        out += [coef, abs(coef)]
    return [float(v) for v in out if math.isfinite(v)]


def echo_path_guesses(unit: str, a: dict[str, Any], twin: Twin) -> list[float]:
    """Lengths [m or mm] that the measured echo delays τ (main peak of the residual–output lag regression, then
    the strongest shorter-lag peaks) imply for a path-length parameter: an extra path c·τ, a round trip c·τ/2,
    and a lateral image source (a wall at distance w beside a path of length L: √(L² + 4w²) − L = c·τ)."""
    u = (unit or "").strip().lower()
    c = ev.sound_speed(twin)
    if u not in ("m", "mm") or not c:
        return []
    k = 1e3 if u == "mm" else 1.0
    taus = [a["echo"].get("lag_s", float("nan"))] + [t for t in a["echo"].get("short_lags_s", []) if math.isfinite(t)]
    L = getattr(twin.params, "distance_m", None)
    out: list[float] = []
    for j, t in enumerate(taus):
        if not math.isfinite(t) or t <= 0:
            continue
        if j == 0:
            out += [k * c * t, k * c * t / 2]
        if isinstance(L, (int, float)) and L > 0:
            out += [k * math.sqrt(max((L + c * t) ** 2 - L * L, 0.0)) / 2]
    return [float(v) for v in out if math.isfinite(v) and v > 0]


def core_for(twin: Twin, core: Sequence[str]) -> list[str]:
    """Core calibration parameters that act in this configuration: a parameter that belongs only to effects
    that are switched off has no effect on the output and is not fitted."""
    owned_off: set[str] = set()
    owned_on: set[str] = set()
    for e, spec in twin.EFFECTS.items():
        (owned_on if e in twin.effects else owned_off).update(spec.params.values())
    return [c for c in core if c not in owned_off or c in owned_on]


def effect_fields(twin: Twin, fields: Iterable[str]) -> list[str]:
    """The numeric, non-integer parameters of ``fields``: the ones least squares fits (integers such as element
    counts and bit depths are structural choices of the configuration and kept as given)."""
    fields = list(fields)
    return [f for f in numeric_fields(twin, fields) if f not in int_fields(twin, fields)]


def quant_params(twin: Twin, effect: str, step: float) -> dict[str, float]:
    """Parameters of a quantisation effect from the measured lattice step: the step itself, or the bit count
    that gives it over the configured range (LSB = 2·range/2^bits)."""
    fields = list(twin.EFFECTS[effect].params.values())
    bits = [f for f in fields if "bit" in f.lower()]
    rng = [f for f in fields if "range" in f.lower()]
    if bits and rng:
        r = float(getattr(twin.params, rng[0]))
        return {bits[0]: float(np.log2(2 * r / step)), rng[0]: r}
    floats = [f for f in fields if isinstance(getattr(twin.params, f, None), float)]
    return {floats[0]: float(step)} if floats else {}


def fmt_params(p: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v:.4g}" if isinstance(v, (int, float)) else f"{k}={v}" for k, v in p.items())
