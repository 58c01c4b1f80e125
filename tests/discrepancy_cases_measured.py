"""Cases of measured-data robustness for the discrepancy tests: a default effect mis-sized ×3, two hidden effects at
once, and effects outside the catalog written here independently of the twin (a dead zone and a backlash of the
amplifier input, an unmodelled resonance of the mount added to the output, a butterfly loop of a bipolar drive
added to the bare twin's output).

Records reuse :func:`discrepancy_cases.records` (steps at 1 kHz, multisine / broadband at 10 kHz with sine
validation), so that every case costs a few seconds of simulation.
"""

from __future__ import annotations

import math

import numpy as np
from discrepancy_cases import records
from scipy import signal as sps

from sysid.data.record import Record

# default effect → (parameter, factor, data kind)
MISSIZED = {
    "creep": ("creep_per_decade", 3.0, "steps"),
    "sensor_lowpass": ("sensor_bandwidth_hz", 1.0 / 3.0, "broadband"),
}

# pairs of hidden effects of the cantilever (start: the default twin without both) → data kind and drawn parameters
PAIRS = {
    ("creep", "thermal_drift"): (
        "steps",
        {"creep_per_decade": (0.015, 0.03), "thermal_drift_um": (1.5, 3.0), "thermal_tau_s": (1.0, 3.0)},
    ),
    ("saturation", "input_delay"): ("multisine", {"sat_voltage_v": (70.0, 110.0), "input_delay_s": (2e-4, 6e-4)}),
}

# pairs of the acoustic twin (ranges as for the single effects in discrepancy_cases.ACOUSTIC)
ACOUSTIC_PAIRS = {
    ("amplifier_compression", "wall_echo"): (
        "multisine",
        {"amp_sat_v": (60.0, 110.0), "wall_distance_m": (0.02, 0.05), "wall_coupling": (0.1, 0.3)},
    ),
}

OUTSIDE = ("dead_zone", "backlash", "resonance")


def _twin():
    from twins.cantilever import CantileverTwin

    return CantileverTwin


def missized_case(effect: str, seed: int):
    """(start = default twin, est, val, true value, field): the data have ``effect``'s parameter × factor."""
    cls = _twin()
    field, factor, kind = MISSIZED[effect]
    base = cls.from_options(seed=seed)
    true = float(getattr(base.params, field)) * factor
    truth = base.with_params(**{field: true})
    est, val = records("cantilever", truth, kind, seed)
    return cls.from_options(seed=0), est, val, true, field


def pair_case(pair: tuple[str, str], seed: int):
    """(start = default twin without both effects, est, val, true parameters); a pair of :data:`PAIRS` (cantilever)
    or :data:`ACOUSTIC_PAIRS`."""
    if pair in ACOUSTIC_PAIRS:
        from twins.acoustic import AcousticTwin as cls

        name, (kind, spec) = "acoustic", ACOUSTIC_PAIRS[pair]
    else:
        cls, name, (kind, spec) = _twin(), "cantilever", PAIRS[pair]
    rng = np.random.default_rng(5000 + seed)
    params = {k: float(rng.uniform(*v)) for k, v in spec.items()}
    base = cls.from_options(seed=seed)
    truth = cls(base.with_params(**params).params, set(base.effects) | set(pair), seed)
    est, val = records(name, truth, kind, seed)
    return cls.from_options(seed=0, without=list(pair)), est, val, params


def dead_zone(u: np.ndarray, width: float) -> np.ndarray:
    """Amplifier dead zone: no output for |u| < width, u ∓ width beyond."""
    return np.sign(u) * np.maximum(np.abs(u) - width, 0.0)


def backlash(u: np.ndarray, width: float) -> np.ndarray:
    """Mechanical backlash (play of half-width ``width``) between the command and the actuator."""
    out = np.empty_like(u)
    x = 0.0
    for i, v in enumerate(u):
        x = min(max(x, v - width), v + width)
        out[i] = x
    return out


def butterfly(u: np.ndarray, width: float, e0: float) -> np.ndarray:
    """Butterfly loop of a bipolar drive: the square of a saturating hysteretic polarisation,
    P = tanh(play(u)/e0) with a play (backlash) operator of half-width ``width`` [V] standing for the coercive
    field — rate independent, P switches sign where the drive passes ∓``width`` on its way up / down, so P²
    (strain ∝ P², electrostriction of the switched domains) dips to 0 there and gives the two wings."""
    return np.tanh(backlash(u, width) / e0) ** 2


def resonance(y: np.ndarray, fs: float, f0: float, zeta: float, share: float) -> np.ndarray:
    """Adds ``share``× the resonant part of an extra 2nd-order mode at f0 (a mount mode): y + share·(R(z)y − y),
    R the bilinear transform of ω₀²/(s² + 2ζω₀s + ω₀²) (DC gain 1, so only the ringing is added)."""
    w0 = 2 * math.pi * f0
    b, a = sps.bilinear([w0 * w0], [1.0, 2 * zeta * w0, w0 * w0], fs)
    yr = sps.lfilter(b, a, y - y[0]) + y[0]
    return y + share * (yr - y)


def outside_case(kind: str, seed: int):
    """(start = default twin, est, val, description): data the catalog cannot represent."""
    cls = _twin()
    rng = np.random.default_rng(7000 + seed)
    truth = cls.from_options(seed=seed)
    est0, val0 = records("cantilever", truth, "multisine", seed)
    tv = type(truth)(truth.params, truth.effects, seed + 7919)
    if kind == "dead_zone":
        w = float(rng.uniform(8.0, 15.0))
        f = lambda tw, rec: tw.simulate(dead_zone(rec.u, w), rec.fs)  # noqa: E731
    elif kind == "backlash":
        w = float(rng.uniform(5.0, 10.0))
        f = lambda tw, rec: tw.simulate(backlash(rec.u, w), rec.fs)  # noqa: E731
    elif kind == "resonance":
        w = float(rng.uniform(120.0, 250.0))
        f = lambda tw, rec: resonance(tw.simulate(rec.u, rec.fs), rec.fs, w, 0.02, 0.15)  # noqa: E731
    else:
        raise ValueError(kind)
    est = Record(u=est0.u, y=f(truth, est0), fs=est0.fs, units=est0.units, meta=dict(est0.meta), source=est0.source)
    val = Record(u=val0.u, y=f(tv, val0), fs=val0.fs, units=val0.units, meta=dict(val0.meta), source=val0.source)
    return cls.from_options(seed=0), est, val, {"kind": kind, "value": w}


def butterfly_case(seed: int):
    """(start = the bare twin, est, val, description): the bare cantilever simulation (no optional effect, no
    noise; multisine ±100 V estimation, 1–200 Hz sines validation) plus a butterfly loop
    a·tanh(play(u, w)/e0)² (:func:`butterfly`; w 15–30 V, e0 15–30 V, a 10–20 % of the estimation output's
    standard deviation) and white noise of 1 % of each record's output standard deviation. No catalog effect is
    an even function of a hysteretic state of the drive."""
    cls = _twin()
    rng = np.random.default_rng(9000 + seed)
    bare = cls.from_options(effects="none", seed=seed)
    est0, val0 = records("cantilever", bare, "multisine", seed)
    w, e0, share = float(rng.uniform(15.0, 30.0)), float(rng.uniform(15.0, 30.0)), float(rng.uniform(0.10, 0.20))
    a = share * float(np.std(est0.output))
    out = []
    for rec in (est0, val0):
        y = rec.output + a * butterfly(rec.u, w, e0)
        y = y + 0.01 * float(np.std(y)) * rng.standard_normal(y.size)
        out.append(Record(u=rec.u, y=y, fs=rec.fs, units=rec.units, meta=dict(rec.meta), source=rec.source))
    desc = {"kind": "butterfly", "width_v": w, "e0_v": e0, "amplitude_um": a, "share_of_std": share}
    return cls.from_options(effects="none", seed=0), out[0], out[1], desc


def creep_stack_record(seed: int = 0, fs: float = 100.0, hold_s: float = 20.0, rate: float = 0.03) -> Record:
    """A PZT-stack creep test as a lab records it (the project has no measured one): 0 V for 2 s, then holds of
    ``hold_s`` alternating 1400 V and 1000 V (four holds), y in µm at ``fs``; simulated with the default
    cantilever twin whose creep rate is ``rate`` per decade (twice the default) and whose amplifier reaches
    1.5 kV, with its measurement noise and quantisation."""
    cls = _twin()
    n0, n1 = int(2 * fs), int(hold_s * fs)
    u = np.concatenate([np.zeros(n0)] + [np.full(n1, v) for v in (1400.0, 1000.0, 1400.0, 1000.0)])
    truth = cls.from_options(seed=seed).with_params(amp_limit_v=1500.0, creep_per_decade=rate)
    y = truth.simulate(u, fs)
    return Record(
        u=u,
        y=y,
        fs=fs,
        units={"u": "V", "y": "um"},
        meta={"what": "simulated PZT-stack creep test"},
        source="creep_stack",
    )
