"""Model-agnostic effects: what sits between a model and the measurement, for any twin.

Each effect wraps a simulator's input or output and needs nothing of its physics: a pure input delay, a drive
low-pass (the amplifier's bandwidth), a drive compression (soft limiter), a sensor low-pass, an echo of the output,
electrical crosstalk of the input, offset and gain drift, a constant sensor offset, and a quantiser.
:data:`GENERIC_EFFECTS` is their catalog (id, description, residual signature, parameters with units);
:data:`GENERIC_FIELDS` the parameter fields, each with a documented default range and a rule for its range from the
records (:func:`data_ranges`); :func:`apply_input` and :func:`apply_output` the sample-level implementations that
:class:`twins.external.ExternalTwin` wraps around a user's Python model or FMU.

The shipped twins build on the same catalog entries: the cantilever's ``input_delay``, ``sensor_lowpass``,
``thermal_drift``, ``slow_drift`` and ``saturation`` are :func:`specialise`-d from ``input_delay``,
``sensor_lowpass``, ``offset_drift``, ``slow_drift`` and ``drive_compression`` (same law, the twin's own field
names and signature wording; its compiled kernel applies them inside its sub-steps). The sample-level laws are
those of the cantilever kernel: delay by linear interpolation between samples (zero before the start; a model
that starts at an operating point holds its first input value there), the soft
limiter v = u/(1 + |u/V_s|^p)^(1/p), the drift D·(1 − e^(−t/τ)) (settling) and r·t + a·sin(2πt/P) + b·(1 − cos(2πt/P))
(the slow drift: a ramp and a slow cycle) with t = k/fs; the sensor is the 2nd-order
Butterworth low-pass ω_c²/(s² + √2·ω_c·s + ω_c²) discretised with a first-order hold of the sampled output
(Franklin & Powell §6.3) and started in steady state at the first output sample.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from scipy import signal

from twins.base import EffectSpec
from twins.paramfields import pfield

__all__ = [
    "GENERIC_EFFECTS",
    "GENERIC_FIELDS",
    "INPUT_SIDE",
    "GenericField",
    "specialise",
    "data_ranges",
    "generic_params_class",
    "apply_input",
    "apply_output",
    "delay_input",
    "soft_limit",
    "drive_lowpass",
    "sensor_lowpass",
    "drift",
]

_T = "generic"


@dataclasses.dataclass(frozen=True)
class GenericField:
    """A parameter of a generic effect: default, unit (``{u}``/``{y}`` stand for the record's units), default
    range and its range from the records (``rule(umax, yspan, fs, duration) -> (lo, hi)``)."""

    default: float
    unit: str
    lo: float
    hi: float
    doc: str
    rule: Callable[[float, float, float, float], tuple[float, float]]


def _span(y: float) -> float:
    return y if y > 0 else 1.0


GENERIC_FIELDS: dict[str, GenericField] = {
    "input_delay_s": GenericField(
        0.0, "s", 0.0, 1e3, "pure delay of the input", lambda um, ys, fs, T: (0.0, min(50.0 / fs, 0.1 * T))
    ),
    "compression_knee": GenericField(
        1e3,
        "{u}",
        1e-9,
        1e12,
        "knee V_s of the soft limiter v = u/(1+|u/V_s|^p)^(1/p)",
        lambda um, ys, fs, T: (0.2 * _span(um), 10.0 * _span(um)),
    ),
    "compression_sharpness": GenericField(
        4.0, "1", 1.0, 20.0, "sharpness p of the soft limiter (large p: hard clip)", lambda um, ys, fs, T: (1.0, 20.0)
    ),
    "sensor_bandwidth_hz": GenericField(
        1e3,
        "Hz",
        1e-9,
        1e12,
        "corner of the 2nd-order Butterworth sensor low-pass (an analog part: above Nyquist it is a sub-sample lag)",
        lambda um, ys, fs, T: (fs / 500.0, 10.0 * fs),
    ),
    "drive_bandwidth_hz": GenericField(
        1e3,
        "Hz",
        1e-9,
        1e12,
        "corner of the drive's 1st-order low-pass (an amplifier's bandwidth; above Nyquist a sub-sample lag)",
        lambda um, ys, fs, T: (fs / 500.0, 10.0 * fs),
    ),
    "echo_delay_s": GenericField(
        1e-3, "s", 0.0, 1e6, "delay of the output echo", lambda um, ys, fs, T: (1.0 / fs, min(200.0 / fs, 0.25 * T))
    ),
    "echo_gain": GenericField(
        0.0, "1", -1.0, 1.0, "amplitude of the output echo (share of the output)", lambda um, ys, fs, T: (-1.0, 1.0)
    ),
    "crosstalk_gain": GenericField(
        0.0,
        "{y}/{u}",
        -1e12,
        1e12,
        "share of the input added to the output",
        lambda um, ys, fs, T: (-_span(ys) / _span(um), _span(ys) / _span(um)),
    ),
    "drift_offset": GenericField(
        0.0,
        "{y}",
        -1e12,
        1e12,
        "final value D of the offset drift D·(1 − e^(−t/τ))",
        lambda um, ys, fs, T: (-2.0 * _span(ys), 2.0 * _span(ys)),
    ),
    "drift_tau_s": GenericField(
        1.0, "s", 1e-12, 1e12, "time constant τ of the offset drift", lambda um, ys, fs, T: (10.0 / fs, 10.0 * T)
    ),
    "sensor_offset": GenericField(
        0.0,
        "{y}",
        -1e12,
        1e12,
        "constant offset c of the reading y + c (the sensor's zero is not the model's zero)",
        lambda um, ys, fs, T: (-_span(ys), _span(ys)),
    ),
    "drift_rate": GenericField(
        0.0,
        "{y}/s",
        -1e12,
        1e12,
        "ramp r of the offset drift (r·t)",
        lambda um, ys, fs, T: (-2.0 * _span(ys) / T, 2.0 * _span(ys) / T),
    ),
    "drift_sin": GenericField(
        0.0,
        "{y}",
        -1e12,
        1e12,
        "amplitude a of the drift's slow sine a·sin(2πt/P)",
        lambda um, ys, fs, T: (-2.0 * _span(ys), 2.0 * _span(ys)),
    ),
    "drift_cos": GenericField(
        0.0,
        "{y}",
        -1e12,
        1e12,
        "amplitude b of the drift's slow b·(1 − cos(2πt/P))",
        lambda um, ys, fs, T: (-2.0 * _span(ys), 2.0 * _span(ys)),
    ),
    "drift_period_s": GenericField(
        100.0, "s", 1e-12, 1e12, "period P of the drift's slow oscillation", lambda um, ys, fs, T: (0.5 * T, 20.0 * T)
    ),
    "gain_drift": GenericField(
        0.0,
        "1",
        -0.9,
        10.0,
        "final relative gain change g of y·(1 + g·(1 − e^(−t/τ)))",
        lambda um, ys, fs, T: (-0.5, 0.5),
    ),
    "gain_drift_tau_s": GenericField(
        1.0, "s", 1e-12, 1e12, "time constant τ of the gain drift", lambda um, ys, fs, T: (10.0 / fs, 10.0 * T)
    ),
    "gain_drift_rate": GenericField(
        0.0,
        "1/s",
        -1e12,
        1e12,
        "ramp ρ of a gain drift that has not settled (ρ·t, the relative gain change per second)",
        lambda um, ys, fs, T: (-0.5 / T, 0.5 / T),
    ),
    "quant_step": GenericField(
        1e-6,
        "{y}",
        1e-15,
        1e12,
        "step of the output quantiser",
        lambda um, ys, fs, T: (1e-5 * _span(ys), 0.05 * _span(ys)),
    ),
}

GENERIC_EFFECTS: dict[str, EffectSpec] = {
    "input_delay": EffectSpec(
        "input_delay",
        _T,
        "pure delay of the input (fractional samples by linear interpolation)",
        "residual ∝ τ·dy/dt: phase lag growing linearly with frequency (2π f τ), cross-correlation of the "
        "outputs peaks at lag τ·fs; gain unchanged",
        {"delay": "input_delay_s"},
        group="lag",
    ),
    "drive_lowpass": EffectSpec(
        "drive_lowpass",
        _T,
        "1st-order low-pass of the drive 1/(1 + s/ω_c): the bandwidth of the amplifier that drives the model",
        "residual grows with frequency, phase lag ≈ f/f_c rad before the model; at f ≪ f_c a delay of 1/(2π f_c), "
        "which a pure delay gives alike",
        {"bandwidth": "drive_bandwidth_hz"},
        group="lag",
    ),
    "drive_compression": EffectSpec(
        "drive_compression",
        _T,
        "soft limiter of the drive v = u/(1 + |u/V_s|^p)^(1/p) (amplifier or actuator)",
        "output compressed at large |u| only, odd harmonics growing with amplitude; residual ∝ −u|u|^p near the "
        "peaks, none at small u",
        {"knee": "compression_knee", "sharpness": "compression_sharpness"},
    ),
    "sensor_lowpass": EffectSpec(
        "sensor_lowpass",
        _T,
        "2nd-order Butterworth low-pass of the sensor",
        "residual grows with frequency: phase lag ≈ √2·f/f_c rad and roll-off above f_c; nothing at low frequency",
        {"bandwidth": "sensor_bandwidth_hz"},
        group="lag",
    ),
    "output_echo": EffectSpec(
        "output_echo",
        _T,
        "echo of the output: y + a·y(t − τ) (reflection, multipath)",
        "residual is a delayed, scaled copy of the simulated output: their cross-correlation peaks at τ",
        {"delay": "echo_delay_s", "gain": "echo_gain"},
    ),
    "input_crosstalk": EffectSpec(
        "input_crosstalk",
        _T,
        "electrical crosstalk: a share of the input added to the output",
        "residual correlated with u at lag 0, with no dynamics of the model",
        {"gain": "crosstalk_gain"},
    ),
    "offset_drift": EffectSpec(
        "offset_drift",
        _T,
        "additive drift D·(1 − e^(−t/τ)) of the reading, independent of the input",
        "slow monotone trend in the residual, present even at u = 0; no correlation with u",
        {"amplitude": "drift_offset", "tau": "drift_tau_s"},
        group="drift",
        time_varying=True,
    ),
    "slow_drift": EffectSpec(
        "slow_drift",
        _T,
        "additive slow drift of the reading that has not settled: a ramp and a slow cycle of any phase, "
        "r·t + a·sin(2πt/P) + b·(1 − cos(2πt/P)) (zero at t = 0), independent of the input",
        "slow trend in the residual (a ramp, a slow swing or turn), present even at u = 0; no correlation with u",
        {"rate": "drift_rate", "sine": "drift_sin", "cosine": "drift_cos", "period": "drift_period_s"},
        group="drift",
        time_varying=True,
    ),
    "sensor_offset": EffectSpec(
        "sensor_offset",
        _T,
        "constant offset of the reading: y + c (the sensor's zero is not the model's zero: a level sensor above "
        "the outlet, a bridge not nulled)",
        "residual with a constant part from the first sample on; where the model is nonlinear in its output "
        "(a square-root outflow, a saturation) the model's own parameters cannot absorb it",
        {"offset": "sensor_offset"},
    ),
    "gain_drift": EffectSpec(
        "gain_drift",
        _T,
        "slow change of the gain, settling or not: y·(1 + g·(1 − e^(−t/τ)) + ρ·t)",
        "residual ∝ y with a weight growing slowly over the record",
        {"gain": "gain_drift", "tau": "gain_drift_tau_s", "rate": "gain_drift_rate"},
        # y·g(t) = ȳ·g(t) + (y − ȳ)·g(t): on an output that varies little about a large mean (a level, a
        # position held near an operating point) a gain drift is an additive drift to the data but for its small
        # second term, so it is judged with the additive drifts (benchmark seed 516, a cascaded-tanks gain sag of
        # 1.8 % about a 5 V level: validation NRMSE slow_drift 0.0154, gain_drift 0.0171, offset_drift 0.0226)
        group="drift",
        time_varying=True,
    ),
    "output_quantization": EffectSpec(
        "output_quantization",
        _T,
        "quantiser (ADC) with step q on the output",
        "residual uniformly distributed in ±q/2, white, independent of u; output takes values on a q grid",
        {"step": "quant_step"},
    ),
}

#: effects applied to the input, in this order, before the model; the others act on its output
INPUT_SIDE: tuple[str, ...] = ("input_delay", "drive_lowpass", "drive_compression")
#: output effects in the order they act (the quantiser last, as the instrument reads)
OUTPUT_ORDER: tuple[str, ...] = (
    "sensor_lowpass",
    "output_echo",
    "input_crosstalk",
    "gain_drift",
    "offset_drift",
    "slow_drift",
    "sensor_offset",
    "output_quantization",
)


def specialise(effect: str, twin: str, params: Mapping[str, str], **changes: Any) -> EffectSpec:
    """The generic catalog entry ``effect`` for ``twin``: its parameter keys mapped to the twin's fields
    (``params``, same keys), and any field of :class:`EffectSpec` (description, signature, default_on ...)
    in the twin's own words; ``generic`` names ``effect`` (the same cause under a twin's own id)."""
    spec = GENERIC_EFFECTS[effect]
    if set(params) != set(spec.params):
        raise ValueError(f"{effect}: parameter keys {sorted(params)} differ from the catalog's {sorted(spec.params)}")
    return dataclasses.replace(spec, twin=twin, params=dict(params), generic=effect, **changes)


def data_ranges(u: np.ndarray, y: np.ndarray, fs: float) -> dict[str, tuple[float, float]]:
    """Range of every generic field for records with inputs ``u``, outputs ``y`` (concatenated) at ``fs``."""
    umax = float(np.max(np.abs(u))) if np.size(u) else 1.0
    yspan = float(np.ptp(y)) if np.size(y) else 1.0
    duration = np.size(y) / fs
    out: dict[str, tuple[float, float]] = {}
    for k, f in GENERIC_FIELDS.items():
        lo, hi = f.rule(umax, yspan, fs, duration)
        out[k] = (float(lo), float(hi))
    return out


# ------------------------------------------------------------------------------------------------ the laws
def delay_input(u: np.ndarray, delay_s: float, fs: float, before: float = 0.0) -> np.ndarray:
    """``u`` delayed by ``delay_s`` [s]: D whole samples and the fraction μ by linear interpolation, ``before``
    before the first sample (0: the state at rest, as the cantilever kernel's delay line)."""
    dl = max(0.0, float(delay_s) * fs)
    D = int(math.floor(dl + 1e-12))
    mu = max(0.0, dl - D)
    pad = np.concatenate([np.full(D + 1, float(before)), np.asarray(u, float)])
    n = len(u)
    return (1.0 - mu) * pad[1 : n + 1] + mu * pad[:n]


def soft_limit(u: np.ndarray, knee: float, sharpness: float) -> np.ndarray:
    """Soft limiter u/(1 + |u/V_s|^p)^(1/p): slope 1 at small |u|, tends to ±V_s."""
    p = float(sharpness)
    return u / (1.0 + np.abs(u / float(knee)) ** p) ** (1.0 / p)


def _foh_filter(num: list[float], den: list[float], x: np.ndarray, fs: float, before: float) -> np.ndarray:
    """``x`` through the analog filter num(s)/den(s) of unit DC gain, discretised with a first-order hold (exact for
    a signal linear between samples), in steady state at ``before`` before the first sample."""
    b, a, _ = signal.cont2discrete((num, den), 1.0 / fs, method="foh")
    b = np.ravel(b)
    zi = signal.lfilter_zi(b, a) * float(before)
    return signal.lfilter(b, a, np.asarray(x, float), zi=zi)[0]


def drive_lowpass(u: np.ndarray, bandwidth_hz: float, fs: float, before: float = 0.0) -> np.ndarray:
    """``u`` through the 1st-order low-pass 1/(1 + s/ω_c) at ``bandwidth_hz`` (FOH discretisation: exact for a drive
    linear between samples, so a corner above the Nyquist frequency is the sub-sample lag 1/ω_c), in steady state
    at ``before`` before the first sample (0: at rest)."""
    wc = 2.0 * math.pi * float(bandwidth_hz)
    return _foh_filter([wc], [1.0, wc], u, fs, before)


def sensor_lowpass(y: np.ndarray, bandwidth_hz: float, fs: float) -> np.ndarray:
    """``y`` through the 2nd-order Butterworth low-pass at ``bandwidth_hz`` (FOH discretisation), in steady
    state at ``y[0]`` before the first sample."""
    wc = 2.0 * math.pi * float(bandwidth_hz)
    return _foh_filter([wc * wc], [1.0, math.sqrt(2.0) * wc, wc * wc], y, fs, y[0] if len(y) else 0.0)


def drift(
    n: int,
    fs: float,
    amplitude: float,
    tau_s: float,
    rate: float = 0.0,
    sine: float = 0.0,
    cosine: float = 0.0,
    period_s: float = 1.0,
) -> np.ndarray:
    """The slow drift D·(1 − e^(−t/τ)) + r·t + a·sin(2πt/P) + b·(1 − cos(2πt/P)) at t = k/fs, k = 0 … n−1:
    a settling exponential, a ramp that has not settled and a slow cycle (any phase), all zero at t = 0."""
    t = np.arange(n) / fs
    out = float(amplitude) * -np.expm1(-t / float(tau_s))
    if rate or sine or cosine:
        w = 2.0 * math.pi / float(period_s)
        out = out + float(rate) * t + float(sine) * np.sin(w * t) + float(cosine) * (1.0 - np.cos(w * t))
    return out


def apply_input(u: np.ndarray, fs: float, effects: frozenset[str] | set[str], p: Any, held: bool = False) -> np.ndarray:
    """The input the model sees: ``u`` through the input-side effects that are on (fields of ``p``). ``held``: the
    input before the record was its first value (a model that starts at an operating point), else 0 (at rest)."""
    v = np.asarray(u, float)
    if "input_delay" in effects:
        v = delay_input(v, p.input_delay_s, fs, float(v[0]) if held and v.size else 0.0)
    if "drive_lowpass" in effects:
        v = drive_lowpass(v, p.drive_bandwidth_hz, fs, float(v[0]) if held and v.size else 0.0)
    if "drive_compression" in effects:
        v = soft_limit(v, p.compression_knee, p.compression_sharpness)
    return v


def apply_output(y: np.ndarray, u: np.ndarray, fs: float, effects: frozenset[str] | set[str], p: Any) -> np.ndarray:
    """The reading: the model's output ``y`` through the output-side effects that are on (``u`` the input as
    given, for the crosstalk)."""
    y = np.asarray(y, float)
    if "sensor_lowpass" in effects:
        y = sensor_lowpass(y, p.sensor_bandwidth_hz, fs)
    if "output_echo" in effects:
        y = y + p.echo_gain * delay_input(y, p.echo_delay_s, fs)
    if "input_crosstalk" in effects:
        y = y + p.crosstalk_gain * np.asarray(u, float)
    if "gain_drift" in effects:
        y = y * (1.0 + drift(len(y), fs, p.gain_drift, p.gain_drift_tau_s, p.gain_drift_rate))
    if "offset_drift" in effects:
        y = y + drift(len(y), fs, p.drift_offset, p.drift_tau_s)
    if "slow_drift" in effects:
        y = y + drift(len(y), fs, 0.0, 1.0, p.drift_rate, p.drift_sin, p.drift_cos, p.drift_period_s)
    if "sensor_offset" in effects:
        y = y + float(p.sensor_offset)
    if "output_quantization" in effects:
        q = float(p.quant_step)
        y = q * np.floor(y / q + 0.5)
    return y


def generic_params_class(units: Mapping[str, str] | None = None) -> type:
    """A parameter dataclass of the generic fields alone (units with the record's ``u``/``y`` units filled in, or
    the placeholders ``{u}``, ``{y}``): what ``piezotwin list effects`` shows for the catalog itself."""

    def unit(text: str) -> str:
        return text if units is None else text.replace("{u}", units.get("u", "1")).replace("{y}", units.get("y", "1"))

    fields = [
        (k, float, pfield(f.default, unit(f.unit), f.lo, f.hi, f.doc, source="twins.generic_effects"))
        for k, f in GENERIC_FIELDS.items()
    ]
    return dataclasses.make_dataclass("GenericEffectParams", fields)
