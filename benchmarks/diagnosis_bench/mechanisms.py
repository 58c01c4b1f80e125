"""The mechanisms the diagnosis benchmark hides in its records, written here with their own code.

None of them calls the catalog's effect functions (:mod:`twins.generic_effects`, a twin's ``EFFECTS``): an effect
injected through the method's own implementation would test nothing. Each is one physical mechanism whose
parameters are the same in the estimation and the validation record (one limiter, one echo path, one sensor),
sized by one number ``size`` drawn log-uniformly from below the detection limit to large, and acts at one place:

- ``input``: on the drive before the model (a delay line, a limiter, a first-order amplifier, a dead zone, …);
- ``output``: on the model's noise-free output (a sensor, an echo, crosstalk, a drift, a gain sag, …);
- ``core``: the truth is the model with a physical quantity changed (the acoustic gap, the water temperature or
  the fluid), through the twin's own physics, not through an effect switch.

:data:`EXPECTED` says, per twin family, which catalog effect names the mechanism (absent: the mechanism lies
outside that twin's catalog and the honest answer is ``unexplained`` or no confident name).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy import signal

__all__ = ["Mechanism", "MECHANISMS", "EXPECTED", "TWIN_MECHANISMS", "apply_input", "apply_output"]


@dataclasses.dataclass(frozen=True)
class Mechanism:
    """A hidden mechanism: where it acts, its ``size`` range (log-uniform draws) and what ``size`` means."""

    name: str
    where: str  # "input", "output" or "core"
    size_range: tuple[float, float]
    meaning: str


MECHANISMS: dict[str, Mechanism] = {
    m.name: m
    for m in (
        Mechanism("delay", "input", (1e-3, 0.3), "delay × the highest excited frequency [cycles]"),
        Mechanism("limiter", "input", (3e-3, 0.4), "compression of the drive at its peak (1 − out/in)"),
        Mechanism("drive_lowpass", "input", (0.01, 2.0), "highest excited frequency / first-order corner"),
        Mechanism("even", "input", (3e-3, 0.3), "quadratic term of the drive at its peak (k in u + k·u²/|u|max)"),
        Mechanism("dead_zone", "input", (3e-3, 0.2), "dead band half-width / drive peak"),
        Mechanism("backlash", "input", (3e-3, 0.2), "play half-width / drive peak"),
        Mechanism("input_lag", "input", (0.01, 2.0), "highest excited frequency / first-order corner of the drive"),
        Mechanism("sensor_lowpass", "output", (0.01, 2.0), "highest excited frequency / Butterworth corner"),
        Mechanism("echo", "output", (3e-3, 0.3), "echo amplitude re the direct output"),
        Mechanism("crosstalk", "output", (3e-3, 0.3), "crosstalk RMS / output RMS"),
        Mechanism("quantization", "output", (3e-3, 0.5), "quantiser step / output RMS"),
        Mechanism("drift_exp", "output", (3e-3, 0.5), "settled drift / output RMS"),
        Mechanism("drift_slow", "output", (3e-3, 0.5), "largest excursion of a ramp + slow cycle / output RMS"),
        Mechanism("offset", "output", (3e-3, 0.5), "sensor offset / output RMS"),
        Mechanism("gain_sag", "output", (3e-3, 0.3), "relative gain lost by the end of each record"),
        Mechanism("hum", "output", (3e-3, 0.3), "mains hum amplitude / output RMS"),
        Mechanism("quadratic", "output", (3e-3, 0.3), "c in y + c·y²/|y|max (a sensor's even nonlinearity)"),
        Mechanism("creep", "output", (1e-3, 0.08), "creep per decade of time re the static gain"),
        Mechanism("second_mode", "output", (3e-3, 0.3), "share of the static deflection in a second mode"),
        Mechanism("tilt", "output", (0.01, 0.6), "phase spread across the receiver face [carrier periods]"),
        Mechanism("temperature", "core", (5e-4, 8.0), "water temperature error [K]"),
        Mechanism("gap", "core", (3e-7, 3e-3), "plate gap error [m]"),
        Mechanism("fluid", "core", (1.0, 1.0), "another fluid in the tank (no size: the fluid is drawn)"),
    )
}

#: twin family → mechanism → catalog effects that name it right (first the effect itself, then its group)
EXPECTED: dict[str, dict[str, tuple[str, ...]]] = {
    "cantilever": {
        "delay": ("input_delay", "amplifier_bandwidth"),
        "limiter": ("saturation",),
        "drive_lowpass": ("amplifier_bandwidth", "input_delay"),
        "sensor_lowpass": ("sensor_lowpass",),
        "creep": ("creep",),
        "drift_exp": ("thermal_drift", "slow_drift"),
        "drift_slow": ("slow_drift", "thermal_drift"),
        "quantization": ("sensor_quantization",),
        "second_mode": ("second_mode",),
    },
    "acoustic": {
        "limiter": ("amplifier_compression",),
        "even": ("amplifier_even_distortion",),
        "echo": ("wall_echo",),
        "crosstalk": ("crosstalk",),
        "quantization": ("adc_quantization",),
        "temperature": ("temperature_offset", "distance_offset", "fluid_mismatch"),
        "gap": ("distance_offset", "temperature_offset", "fluid_mismatch"),
        "fluid": ("fluid_mismatch", "temperature_offset", "distance_offset"),
        "tilt": ("misalignment",),
    },
    "user": {
        "delay": ("input_delay",),
        "limiter": ("drive_compression",),
        "sensor_lowpass": ("sensor_lowpass",),
        "echo": ("output_echo",),
        "crosstalk": ("input_crosstalk",),
        "drift_exp": ("offset_drift", "slow_drift", "sensor_offset"),
        "drift_slow": ("slow_drift", "offset_drift"),
        "offset": ("sensor_offset", "offset_drift"),
        "gain_sag": ("gain_drift",),
        "quantization": ("output_quantization",),
        "input_lag": ("drive_lowpass", "input_delay"),
    },
}

#: twin family → the mechanisms drawn for it: its catalog's (EXPECTED) and some outside it
TWIN_MECHANISMS: dict[str, tuple[str, ...]] = {
    "cantilever": (*EXPECTED["cantilever"], "gain_sag", "crosstalk", "dead_zone", "backlash", "hum", "quadratic"),
    "acoustic": (*EXPECTED["acoustic"], "gain_sag", "dead_zone", "quadratic"),
    # the drive's lag came last while it lay outside the user catalog; it stays last, so that every seed draws the
    # case it drew before the catalog took it in
    "user": (*(m for m in EXPECTED["user"] if m != "input_lag"), "dead_zone", "backlash", "quadratic", "input_lag"),
}


# ------------------------------------------------------------------------------------------------ drive side
def _limit(u: np.ndarray, shape: str, level: float, p: float = 2.0) -> np.ndarray:
    """A monotone limiter at ``level`` (the input where it starts to bend, in the drive's units)."""
    x = u / level
    if shape == "tanh":
        return level * np.tanh(x)
    if shape == "cubic":  # x − x³/3 up to |x| = 1, then flat at 2/3 (unit small-signal gain)
        xc = np.clip(x, -1.0, 1.0)
        return level * (xc - xc**3 / 3.0)
    if shape == "hardclip":
        return level * np.clip(x, -1.0, 1.0)
    return level * x / (1.0 + np.abs(x) ** (2 * p)) ** (1.0 / (2 * p))  # Rapp with smoothness p


def limiter_level(peak: float, shape: str, compression: float, p: float = 2.0) -> float:
    """The ``level`` at which ``_limit`` compresses a drive of ``peak`` by ``compression`` at that peak."""
    target = (1.0 - compression) * peak
    lo, hi = 1e-6 * peak, 1e6 * peak
    for _ in range(200):  # bisection on the monotone map level -> output at the peak
        mid = math.sqrt(lo * hi)
        out = float(_limit(np.array([peak]), shape, mid, p)[0])
        lo, hi = (mid, hi) if out < target else (lo, mid)
    return math.sqrt(lo * hi)


def _analog(num: list[float], den: list[float], x: np.ndarray, fs: float, at_rest: bool = False) -> np.ndarray:
    """``x`` through the analog filter num(s)/den(s), simulated exactly for an input linear between samples
    (:func:`scipy.signal.lsim`), from steady state at x[0] (at rest at 0 with ``at_rest``).

    A sensor or an amplifier is an analog part: its corner may lie near or above the Nyquist frequency of the
    record (a 16 kHz sensor sampled at 2.3 kHz is a delay of 14 µs). A bilinear map cannot place a corner there;
    clipped below Nyquist, it made such a part a half-sample filter far larger than the drawn size (seeds 20, 118).
    """
    a, b, c, d = signal.tf2ss(num, den)
    x0 = np.zeros(a.shape[0]) if at_rest or not x.size else -np.linalg.solve(a, b[:, 0] * float(x[0]))
    t = np.arange(x.size) / fs
    return np.asarray(signal.lsim((a, b, c, d), x, t, X0=x0)[1], dtype=float)


def _first_order(x: np.ndarray, fc: float, fs: float, at_rest: bool = False) -> np.ndarray:
    """1/(1 + s/ω_c) (:func:`_analog`), started in steady state at x[0] (at rest at 0 with ``at_rest``)."""
    return _analog([1.0], [1.0 / (2 * math.pi * fc), 1.0], x, fs, at_rest)


def _play(u: np.ndarray, r: float) -> np.ndarray:
    """Backlash (play operator) of half-width ``r``, starting centred on u[0]."""
    out = np.empty_like(u)
    z = float(u[0])
    for k, v in enumerate(u.tolist()):
        z = min(max(z, v - r), v + r)
        out[k] = z
    return out


def apply_input(name: str, u: np.ndarray, fs: float, p: dict[str, Any]) -> np.ndarray:
    """The drive after the hidden input-side mechanism ``name`` with parameters ``p``."""
    t = np.arange(u.size) / fs
    if name == "delay":
        return np.interp(t - p["delay_s"], t, u, left=float(u[0]))
    if name == "limiter":
        mid = p["centre"]
        return mid + _limit(u - mid, p["shape"], p["level"], p.get("rapp_p", 2.0))
    if name in ("drive_lowpass", "input_lag"):
        return _first_order(u, p["corner_hz"], fs)
    if name == "even":
        return u + p["k"] * u * u / p["peak"]
    if name == "dead_zone":
        mid = p["centre"]
        d = u - mid
        return mid + np.sign(d) * np.maximum(np.abs(d) - p["width"], 0.0)
    if name == "backlash":
        return _play(u, p["width"])
    raise KeyError(name)


# ------------------------------------------------------------------------------------------------ output side
def _butter2(y: np.ndarray, fc: float, fs: float) -> np.ndarray:
    """The 2nd-order Butterworth low-pass ω_c²/(s² + √2·ω_c·s + ω_c²) (:func:`_analog`)."""
    wc = 2 * math.pi * fc
    return _analog([wc * wc], [1.0, math.sqrt(2.0) * wc, wc * wc], y, fs)


def _creep(v: np.ndarray, fs: float, rate: float, gain: float, tau1: float) -> np.ndarray:
    """Logarithmic creep as first-order lags one decade apart from ``tau1``: each decade adds ``rate`` × the
    static deflection ``gain``·v (the Kelvin–Voigt picture of the log law, built here by the generator).

    The lags start at rest at 0 V, as the model they are added to does (the twins start at rest; a drive whose
    first sample is not 0 V is a step at t = 0 for every part of the rig). Started in equilibrium at v[0]
    instead, the creep of a record whose drive starts at −3 V lacked the step's slow transient that the model's
    creep has, and a thermal drift fitted it better than creep itself (seeds 15 and 40)."""
    out = np.zeros_like(v)
    T = v.size / fs
    tau = tau1
    while tau < 30 * T:
        lag = _first_order(v, 1.0 / (2 * math.pi * tau), fs, at_rest=True)
        out += rate * gain * lag
        tau *= 10.0
    return out


def _second_mode(y: np.ndarray, fs: float, f1: float, zeta1: float, f2: float, zeta2: float, share: float):
    """(1 − s)·y + s·(H₂/H₁)·y: a share s of the deflection through a second mode instead of the first (both
    unit-DC second-order sections, simulated as analog filters; the first mode's section is inverted)."""
    w1, w2 = 2 * math.pi * f1, 2 * math.pi * f2
    num = [1 / w1**2, 2 * zeta1 / w1, 1.0]  # H₂/H₁ = (s²/ω₁² + 2ζ₁s/ω₁ + 1)/(s²/ω₂² + 2ζ₂s/ω₂ + 1)
    den = [1 / w2**2, 2 * zeta2 / w2, 1.0]
    ratio = _analog(num, den, y, fs)
    return (1 - share) * y + share * ratio


def apply_output(name: str, y: np.ndarray, u: np.ndarray, fs: float, p: dict[str, Any]) -> np.ndarray:
    """The noise-free output after the hidden output-side mechanism ``name`` (quantisation comes later, after
    the noise, as in an ADC: :func:`quantize`)."""
    t = np.arange(y.size) / fs
    T = y.size / fs
    if name == "sensor_lowpass":
        return _butter2(y, p["corner_hz"], fs)
    if name == "echo":
        d = np.interp(t - p["delay_s"], t, y, left=0.0)
        if p.get("corner_hz"):
            d = _first_order(d, p["corner_hz"], fs)
        return y + p["gain"] * d
    if name == "crosstalk":
        x = np.gradient(u, 1.0 / fs) * p["tau_s"] if p.get("derivative") else u - p.get("centre", 0.0)
        return y + p["gain"] * x
    if name == "drift_exp":
        return y + p["amplitude"] * (1.0 - np.exp(-t / p["tau_s"]))
    if name == "drift_slow":
        w = 2 * math.pi / p["period_s"]
        return y + p["rate"] * t + p["sine"] * np.sin(w * t) + p["cosine"] * (1.0 - np.cos(w * t))
    if name == "offset":
        return y + p["offset"]
    if name == "gain_sag":
        return y * (1.0 - p["sag"] * t / T)
    if name == "hum":
        return y + p["amplitude"] * np.sin(2 * math.pi * p["freq_hz"] * t + p["phase"])
    if name == "quadratic":
        return y + p["c"] * y * y / p["ymax"]
    if name == "creep":
        return y + _creep(p["drive"], fs, p["rate"], p["gain"], p["tau1_s"])
    if name == "second_mode":
        return _second_mode(y, fs, p["f1_hz"], p["zeta1"], p["f2_hz"], p["zeta2"], p["share"])
    if name == "tilt":  # averaging over arrival times spread symmetrically about the face's centre, an overlap loss
        n = 2 * int(round(p["spread_s"] * fs / 2.0)) + 1
        return p["overlap"] * np.convolve(y, np.ones(n) / n, mode="same")
    if name == "quantization":  # applied after the noise by quantize()
        return y
    raise KeyError(name)


def quantize(y: np.ndarray, step: float, span: float | None = None) -> np.ndarray:
    """A mid-tread quantiser of ``step``, clipping at ±``span`` when given (an ADC's range)."""
    x = np.clip(y, -span, span) if span else y
    return step * np.round(x / step)


INPUT_SIDE: tuple[str, ...] = tuple(m.name for m in MECHANISMS.values() if m.where == "input")
OUTPUT_SIDE: tuple[str, ...] = tuple(m.name for m in MECHANISMS.values() if m.where == "output")
#: a callable that draws a mechanism's parameters: (name, size, context, rng) -> params (see cases.py)
Drawer = Callable[[str, float, dict[str, Any], np.random.Generator], dict[str, Any]]
