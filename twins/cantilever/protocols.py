"""Excitation protocols of the cantilever twin (dissertation §3.1).

- ``thesis-multisine``: the estimation set — n_f = 5000 random-phase components up to 500 Hz, ±100 V,
  8 s at 10 kHz (80 000 samples). Five thousand components up to 500 Hz need a 0.1 Hz grid, i.e. a 10 s
  period; the dissertation's 8 s record is therefore the first 8 s of one 10 s period, which is how it is
  built here (bins 1…5000 of a 10 s period, truncated to 8 s, scaled to a 100 V peak).
- ``thesis-sines``: the validation sets — pure sines at 0.1, 1, 10, 50, 100, 150, 200, 250, 300, 400, 450 and
  500 Hz, "one at a time" (§3.1). The dissertation does not state their durations; here each segment lasts a
  whole number of periods, at least ``min_periods`` and at least ``min_duration_s`` (0.1 Hz: 1 period = 10 s;
  1 Hz: 2 s; ≥ 10 Hz: 0.5 s), starts at phase 0 and ends at 0 V, so the segments join without jumps. The
  segments are concatenated in one Record; ``meta["segments"]`` lists {start, stop, freq_hz} per segment.
- ``steps``: voltage steps 0 → +V → 0 → −V → 0 with long holds (default 20 s each at 1 kHz), which reveal
  creep (log-time tail) and thermal drift.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sysid.config import make_rng
from sysid.errors import ConfigError

__all__ = ["PROTOCOLS", "THESIS_SINE_FREQS_HZ", "multisine_local", "thesis_multisine", "thesis_sines", "steps"]

PROTOCOLS: dict[str, str] = {
    "thesis-multisine": "estimation set of §3.1: 5000 random-phase sines up to 500 Hz, ±100 V, 8 s at 10 kHz",
    "thesis-sines": "validation sets of §3.1: sines 0.1–500 Hz, ±100 V, one segment each (meta['segments'])",
    "steps": "voltage steps 0/+V/0/−V/0 with long holds (creep, drift), 1 kHz",
}

THESIS_SINE_FREQS_HZ = (0.1, 1.0, 10.0, 50.0, 100.0, 150.0, 200.0, 250.0, 300.0, 400.0, 450.0, 500.0)


def multisine_local(fs: float, period_s: float, n_components: int, f_max: float, seed: int | None) -> np.ndarray:
    """One period of a random-phase multisine with equal amplitudes on bins 1…K of a ``period_s`` grid.

    The components sit on f_k = k/period_s up to ``f_max`` (the first ``n_components`` bins); phases are
    uniform in [0, 2π) from ``seed``. Built by an inverse real FFT; unit peak amplitude.
    """
    n = int(round(fs * period_s))
    df = 1.0 / period_s
    kmax = min(int(np.floor(f_max / df + 1e-9)), n_components, n // 2 - 1)
    rng = make_rng(seed, "signal_seed")
    spec = np.zeros(n // 2 + 1, dtype=complex)
    spec[1 : kmax + 1] = np.exp(1j * rng.uniform(0.0, 2.0 * np.pi, kmax))
    x = np.fft.irfft(spec, n)
    return x / np.max(np.abs(x))


def _opt(options: dict[str, Any], key: str, default: Any, kind=float) -> Any:
    if key not in options:
        return default
    v = options.pop(key)
    try:
        out = kind(v)
    except (TypeError, ValueError):
        raise ConfigError(f"protocol option {key}: expected {kind.__name__}, got {v!r}") from None
    if kind is float and not np.isfinite(out):
        raise ConfigError(f"protocol option {key}: must be finite, got {v!r}")
    return out


def thesis_multisine(options: dict[str, Any]) -> tuple[np.ndarray, float, dict[str, Any]]:
    fs = _opt(options, "fs", 10_000.0)
    duration = _opt(options, "duration_s", 8.0)
    amp = _opt(options, "amplitude_v", 100.0)
    n_comp = _opt(options, "components", 5000, int)
    f_max = _opt(options, "f_max_hz", 500.0)
    seed = _opt(options, "signal_seed", 1, int)
    if fs <= 0 or duration <= 0 or amp <= 0 or n_comp < 1 or f_max <= 0:
        raise ConfigError("thesis-multisine: fs, duration_s, amplitude_v, components, f_max_hz must be positive")
    period = n_comp / f_max  # 5000 components up to 500 Hz → 0.1 Hz grid → 10 s period
    if period < duration:
        period = duration
    n = int(round(fs * duration))
    from sysid.signals.excitation import multisine

    u = multisine(
        fs=fs,
        duration=duration,
        band=(1.0 / period, f_max),
        components=n_comp,
        resolution=1.0 / period,
        amplitude=1.0,
        phase="random",
        seed=seed,
    )
    generator = "sysid.signals.multisine"
    u = np.asarray(u, dtype=float)[:n]
    u = amp * u / np.max(np.abs(u))
    meta = {
        "protocol": "thesis-multisine",
        "components": n_comp,
        "f_max_hz": f_max,
        "grid_hz": 1.0 / period,
        "period_s": period,
        "amplitude_v": amp,
        "signal_seed": seed,
        "generator": generator,
        "crest_factor": float(np.max(np.abs(u)) / np.sqrt(np.mean(u**2))),
    }
    return u, fs, meta


def thesis_sines(options: dict[str, Any]) -> tuple[np.ndarray, float, dict[str, Any]]:
    fs = _opt(options, "fs", 10_000.0)
    amp = _opt(options, "amplitude_v", 100.0)
    min_periods = _opt(options, "min_periods", 2, int)
    min_dur = _opt(options, "min_duration_s", 0.5)
    freqs = options.pop("freqs_hz", THESIS_SINE_FREQS_HZ)
    text = freqs
    if isinstance(freqs, str):
        freqs = [f for f in freqs.replace(";", "-").split("-") if f]
    try:
        freqs = [float(f) for f in freqs]
    except (TypeError, ValueError):
        raise ConfigError(
            f"protocol option freqs_hz: expected frequencies in Hz separated by '-', got {text!r}"
        ) from None
    if fs <= 0 or amp <= 0 or min_periods < 1 or not freqs or any(not 0 < f < fs / 2 for f in freqs):
        raise ConfigError("thesis-sines: need fs > 0, amplitude_v > 0, min_periods ≥ 1 and 0 < f < fs/2")
    parts, segs, start = [], [], 0
    for f in freqs:
        periods = max(min_periods, int(np.ceil(min_dur * f - 1e-9)))
        if f < 1.0:  # 0.1 Hz: one period is already 10 s
            periods = 1
        n = int(round(periods * fs / f))
        t = np.arange(n) / fs
        parts.append(amp * np.sin(2 * np.pi * f * t))
        segs.append({"start": start, "stop": start + n, "freq_hz": f, "periods": periods})
        start += n
    u = np.concatenate(parts)
    meta = {"protocol": "thesis-sines", "amplitude_v": amp, "segments": segs}
    return u, fs, meta


def steps(options: dict[str, Any]) -> tuple[np.ndarray, float, dict[str, Any]]:
    fs = _opt(options, "fs", 1000.0)
    level = _opt(options, "level_v", 80.0)
    hold = _opt(options, "hold_s", 20.0)
    if fs <= 0 or hold <= 0:
        raise ConfigError("steps: fs and hold_s must be positive")
    n = int(round(hold * fs))
    levels = [0.0, level, 0.0, -level, 0.0]
    u = np.concatenate([np.full(n, v) for v in levels])
    segs = [{"start": i * n, "stop": (i + 1) * n, "level_v": v} for i, v in enumerate(levels)]
    meta = {"protocol": "steps", "level_v": level, "hold_s": hold, "segments": segs}
    return u, fs, meta


BUILDERS = {"thesis-multisine": thesis_multisine, "thesis-sines": thesis_sines, "steps": steps}
