"""The records of a benchmark case: the configured model, the hidden mechanism by the generator's code, noise.

:func:`make_records` returns the model to diagnose (as its user configured it), the estimation and validation
records, the noise added to each, the mechanism's parameters and its realised size: the RMS of what it changes
in the noise-free estimation output over that output's RMS (the size the detection limit is stated in,
comparable across mechanisms).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal

from sysid.data.record import Record

from . import mechanisms as mech
from .cases import ACOUSTIC_BAND, Case, _band, excitation, start_twin

__all__ = ["make_records", "draw_params"]


def draw_params(case: Case, twin: Any, u: np.ndarray, y: np.ndarray, rng: np.random.Generator) -> dict[str, Any]:
    """The mechanism's parameters for ``size`` (the estimation drive ``u`` and noise-free output ``y`` give the
    scales), drawn from ``rng``; the same parameters act on both records."""
    name, s, fs = case.mechanism, float(case.size or 0.0), case.fs
    f_hi = _band(case)[1]
    y_rms = float(np.std(y)) or 1.0
    T = case.n / fs
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    if name == "delay":
        return {"delay_s": s / f_hi}
    if name == "limiter":
        shape = str(rng.choice(["tanh", "cubic", "hardclip", "rapp"]))
        p = float(rng.uniform(1.0, 4.0))
        return {"shape": shape, "rapp_p": p, "centre": case.centre, "level": mech.limiter_level(case.peak, shape, s, p)}
    if name in ("drive_lowpass", "input_lag"):
        return {"corner_hz": f_hi / s}
    if name == "even":
        return {"k": s * sign, "peak": case.peak}
    if name in ("dead_zone", "backlash"):
        return {"width": s * case.peak, "centre": case.centre}
    if name == "sensor_lowpass":
        return {"corner_hz": f_hi / s}
    if name == "echo":
        if case.model == "acoustic":
            L, c = twin.params.distance_m, 1480.0
            w = float(rng.uniform(0.005, 0.06))
            corner = float(rng.choice([0.0, rng.uniform(0.5e6, 5e6)]))
            return {"delay_s": (math.hypot(L, 2 * w) - L) / c, "gain": s * sign, "corner_hz": corner}
        return {"delay_s": float(rng.integers(2, 41)) / fs, "gain": s * sign, "corner_hz": 0.0}
    if name == "crosstalk":
        deriv = case.model == "acoustic" and rng.uniform() < 0.5
        x = np.gradient(u, 1.0 / fs) / (2 * math.pi * ACOUSTIC_BAND[1]) if deriv else u - case.centre
        gain = s * sign * y_rms / (float(np.std(x)) or 1.0)
        return {
            "gain": gain,
            "derivative": deriv,
            "tau_s": 1.0 / (2 * math.pi * ACOUSTIC_BAND[1]),
            "centre": case.centre,
        }
    if name == "quantization":
        return {"step": s * y_rms}
    if name == "drift_exp":
        return {"amplitude": s * y_rms * sign, "tau_s": T * float(np.exp(rng.uniform(math.log(0.1), math.log(3.0))))}
    if name == "drift_slow":
        period = T * float(np.exp(rng.uniform(0.0, math.log(10.0))))
        a, b, r = rng.standard_normal(3)
        scale = s * y_rms / max(abs(a) + 2 * abs(b) + abs(r), 1e-9)
        return {"rate": r * scale / T, "sine": a * scale, "cosine": b * scale, "period_s": period}
    if name == "offset":
        return {"offset": s * y_rms * sign}
    if name == "gain_sag":
        return {"sag": s}
    if name == "hum":
        return {"amplitude": s * y_rms, "freq_hz": float(rng.choice([50.0, 60.0, 100.0, 120.0])), "phase": 1.0}
    if name == "quadratic":
        return {"c": s * sign, "ymax": float(np.max(np.abs(y))) or 1.0}
    if name == "creep":
        p = twin.params
        return {"rate": s, "gain": p.gain_um_per_v, "tau1_s": p.creep_tau_min_s}
    if name == "second_mode":
        p = twin.params
        return {"share": s, "f1_hz": p.f1_hz, "zeta1": p.zeta1, "f2_hz": p.mode_ratio * p.f1_hz, "zeta2": p.zeta2}
    if name == "tilt":
        return {"spread_s": s / 1.1e6, "overlap": 1.0 - 0.1 * min(s, 1.0)}
    if name == "temperature":
        return {"set": {"temperature_c": float(twin.params.temperature_c + sign * s)}, "delta": sign * s}
    if name == "gap":
        return {"set": {"distance_m": float(twin.params.distance_m + sign * s)}, "delta": sign * s}
    if name == "fluid":
        from twins.acoustic.fluids import FLUID_NAMES

        return {"set": {"fluid": str(rng.choice([f for f in FLUID_NAMES if f != twin.params.fluid]))}}
    raise KeyError(name)


def _noise(case: Case, y: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    w = rng.standard_normal(y.size)
    if case.noise_ar:
        w = signal.lfilter([1.0], [1.0, -case.noise_ar], w)
    return case.noise * (float(np.std(y)) or 1.0) * w / (float(np.std(w)) or 1.0)


def _truth(case: Case, twin: Any, p: dict[str, Any], u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(noise-free output of the configured model, of the truth) for the drive ``u``."""
    fs, name = case.fs, case.mechanism
    y0 = twin.simulate(u, fs)
    if name is None:
        return y0, y0
    info = mech.MECHANISMS[name]
    if info.where == "core":
        return y0, twin.with_params(**p["set"]).simulate(u, fs)
    if info.where == "input":
        return y0, twin.simulate(mech.apply_input(name, u, fs, p), fs)
    if name == "creep":
        p = {**p, "drive": u}
    if name == "second_mode":
        return y0, y0 + _fine_increment(twin, name, u, fs, p)
    return y0, mech.apply_output(name, y0, u, fs, p)


#: samples per period of the second mode on the grid its increment is computed on
MODE_GRID = 20


def _fine_increment(twin: Any, name: str, u: np.ndarray, fs: float, p: dict[str, Any]) -> np.ndarray:
    """What output mechanism ``name`` adds to the model's output, computed on a grid K times finer than the
    record's (the drive a first-order hold, as the twin takes it) and read at the record's samples. A second mode
    applied as H₂/H₁ to the sampled output amplifies the error of interpolating that output between samples by up
    to (f₂/f₁)² = 39: below about 10 kHz sampling (f₂ above the Nyquist frequency) the result was 16–39 % of the
    output's RMS away from the modal response itself (the twin's own second mode, simulated from the drive);
    on a grid of ``MODE_GRID`` samples per period of f₂ the two agree within 0.5 %."""
    k = max(1, math.ceil(MODE_GRID * float(p["f2_hz"]) / fs))
    t = np.arange(u.size) / fs
    uf = np.interp(np.arange((u.size - 1) * k + 1) / (fs * k), t, u)
    yf = twin.simulate(uf, fs * k)
    return (mech.apply_output(name, yf, uf, fs * k, p) - yf)[::k]


def make_records(case: Case) -> dict[str, Any]:
    """The configured model, its two records and the truth of one case (module docstring)."""
    rng = np.random.default_rng([case.seed, 47])
    twin = start_twin(case)
    u_est, u_val = excitation(case, case.est_kind, rng), excitation(case, case.val_kind, rng)
    params: dict[str, Any] = {}
    if case.mechanism is not None:
        params = draw_params(case, twin, u_est, twin.simulate(u_est, case.fs), rng)
    recs, sizes, noises = [], [], []
    for u in (u_est, u_val):
        y0, y = _truth(case, twin, params, u)
        if case.mechanism == "quantization":  # the quantiser acts after the noise: its error RMS is step/√12
            sizes.append(float(params["step"] / math.sqrt(12.0) / (np.std(y0) or 1.0)))
        else:
            sizes.append(float(np.std(y - y0) / (np.std(y0) or 1.0)))
        noises.append(_noise(case, y, rng))
        y = y + noises[-1]
        if case.mechanism == "quantization":
            y = mech.quantize(y, params["step"])
        recs.append(Record(u=u, y=y, fs=case.fs, units=dict(twin.units), source=f"case {case.seed}"))
    return {
        "twin": twin,
        "est": recs[0],
        "val": recs[1],
        "params": params,
        "size_est": sizes[0],
        "size_val": sizes[1],
        "noise": tuple(noises),  # the noise added to each record (what a perfect model leaves)
    }
