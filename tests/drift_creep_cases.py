"""Slow drifts and multi-time-constant creep injected by test code (not the twin's own laws) on bare cantilever
simulations, with 1 % output noise: the cases behind the drift and creep family tests.

The drift is a ramp plus a slow sine of the time since the record's start, r·t + A·(sin(2πt/P + φ) − sin φ),
added to both records (the twin's drift also runs from each record's start); the creep is a sum of first-order
lags of the drive, Σ g_i·d·v/(τ_i s + 1) with two time constants a decade or more apart, integrated here with
scipy (FOH of the drive), not with the twin's kernel.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from sysid.data.record import Record

HOLD_S = 2.0  # steps at 1 kHz: 5 levels × 2 s = 10 000 samples per record
NOISE_SHARE = 0.01  # σ of the added noise, share of the clean output's standard deviation


def _clean_twin(seed: int):
    from twins.cantilever import CantileverTwin

    base = CantileverTwin.from_options(seed=seed)
    return base.with_effects(set(base.effects) - {"measurement_noise", "sensor_quantization"})


def _noisy(rec: Record, y: np.ndarray, sigma: float, seed: int, tag: str) -> Record:
    y = y + sigma * np.random.default_rng(seed).standard_normal(len(y))
    return Record(u=rec.u, y=y, fs=rec.fs, units=rec.units, meta=dict(rec.meta), source=f"{rec.source}+{tag}")


def drift_case(seed: int, val_hold_s: float = HOLD_S):
    """(start = default twin (no drift), est, val, truth, noise NRMSE of val): ramp 0.3–0.6 µm/s plus a sine of
    1.5–3 µm and period 20–40 s (slower than the 10 s record) at a random phase, on 80 V / 60 V steps (the
    validation's steps held ``val_hold_s``: a longer validation record than the estimation's)."""
    from twins.cantilever import CantileverTwin

    rng = np.random.default_rng(500 + seed)
    clean = _clean_twin(seed)
    est = clean.generate("steps", fs=1000.0, hold_s=HOLD_S, level_v=80.0)
    val = clean.generate("steps", fs=1000.0, hold_s=val_hold_s, level_v=60.0)
    truth = {
        "ramp": float(rng.uniform(0.3, 0.6)),
        "amp": float(rng.uniform(1.5, 3.0)),
        "period": float(rng.uniform(20.0, 40.0)),
        "phase": float(rng.uniform(0.0, 2 * np.pi)),
    }

    def drift(n: int, fs: float) -> np.ndarray:
        t = np.arange(n) / fs
        w, ph = 2 * np.pi / truth["period"], truth["phase"]
        return truth["ramp"] * t + truth["amp"] * (np.sin(w * t + ph) - np.sin(ph))

    recs = [
        _noisy(r, r.y + drift(len(r), r.fs), NOISE_SHARE * float(np.std(r.y)), 10 * seed + k, "drift")
        for k, r in enumerate((est, val))
    ]
    noise_nrmse = NOISE_SHARE * float(np.std(val.y)) / float(np.std(recs[1].y))
    return CantileverTwin.from_options(seed=0), recs[0], recs[1], truth, noise_nrmse


def lag_sum(u: np.ndarray, fs: float, gains: list[float], taus: list[float]) -> np.ndarray:
    """Σ g_i·u filtered by 1/(τ_i s + 1), FOH discretisation (scipy), at rest before the first sample."""
    out = np.zeros(len(u))
    for g, tau in zip(gains, taus):
        b, a, _ = signal.cont2discrete(([1.0], [tau, 1.0]), 1.0 / fs, method="foh")
        out += g * signal.lfilter(np.ravel(b), a, u)
    return out


def creep_case(seed: int):
    """(start = default twin with creep off, est, val, truth, noise NRMSE of val): the creep of the data is
    two lags of the drive, g₁ = 0.04–0.06 at τ₁ = 0.05–0.1 s and g₂ = 0.03–0.05 at τ₂ = 3–6 s (× d), steps of
    2 s at 1 kHz — two time constants 1.5–2 decades apart, not the twin's one-per-decade log chain."""
    from twins.cantilever import CantileverTwin

    rng = np.random.default_rng(900 + seed)
    bare = _clean_twin(seed)
    bare = bare.with_effects(set(bare.effects) - {"creep"})
    truth = {
        "g1": float(rng.uniform(0.04, 0.06)),
        "tau1": float(rng.uniform(0.05, 0.1)),
        "g2": float(rng.uniform(0.03, 0.05)),
        "tau2": float(rng.uniform(3.0, 6.0)),
    }
    d = float(bare.params.gain_um_per_v)
    recs, sigma = [], 0.0
    for k, level in enumerate((80.0, 60.0)):
        r = bare.generate("steps", fs=1000.0, hold_s=HOLD_S, level_v=level)
        y = r.y + d * lag_sum(r.u, r.fs, [truth["g1"], truth["g2"]], [truth["tau1"], truth["tau2"]])
        sigma = NOISE_SHARE * float(np.std(y))
        recs.append(_noisy(r, y, sigma, 20 * seed + k, "creep2"))
    noise_nrmse = sigma / float(np.std(recs[1].y))
    start = CantileverTwin.from_options(seed=0, without=["creep"])
    return start, recs[0], recs[1], truth, noise_nrmse
