"""Excitations and the preprocessing recipe of the dissertation's piezoacoustic experiments (§3.2).

Signals come from :mod:`sysid.signals`, the recipe from :mod:`sysid.signals.preprocess` (team signals' agreed API).

- ``thesis-chirp-100ms``: linear chirp 900 → 1350 kHz over 100 ms, 80 mVpp before the amplifier, recorded at
  100 MHz (10⁷ samples) — the first dataset. One sweep; the record starts with the sweep.
- ``thesis-multisine``: 45 000 random-phase lines in 900–1350 kHz, 400 mV peak. §3.2: "The original signal
  contained 1 million points ... truncated to 5 thousand points" and played repeatedly. 45 000 lines over
  450 kHz is a 10 Hz grid, a 0.1 s period; 10⁶ points per period means the generator file was at 10 MS/s
  (``awg_rate_hz``). We build that file, keep its first 5000 points (0.5 ms), repeat them for the record and
  interpolate 10 → 100 MHz (the generator's reconstruction). The repetition has a discontinuity every 0.5 ms,
  as the real one had. (``sysid.signals.thesis_acoustic_multisine(truncate=5000)`` truncates a 100 MHz
  version instead: 50 µs; ``awg_rate_hz=100e6`` reproduces that reading.)
- ``thesis-chirp-1ms``: linear up-chirp 900 → 1350 kHz with a 1 ms sweep time, 150 mVpp, repeated by the
  generator (sweep mode) for the 100 ms record — the validation signal of the second dataset.
- Periodic excitations (multisine, 1 ms chirp) were running before the scope triggered: the twin simulates a
  warm-up of ``warmup_s`` (default: the length of its impulse response, ≈ 5 ms) first and discards it, so the
  record starts in steady state.

Recipe (``preprocess=true``, §3.2): moving average of 100 points, resampling to 6.75 MHz, fifth-order
band-pass 900–1350 kHz (zero phase), truncation to ``keep`` samples from ``start`` (2000 for the multisine and
the 100 ms chirp, 1000 for the 1 ms chirp).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from sysid.data.record import Record
from sysid.errors import ConfigError

__all__ = ["PROTOCOLS", "BAND_HZ", "excitation", "recipe_steps", "apply_recipe", "RECIPE_KEEP"]

BAND_HZ = (900e3, 1350e3)  # §3.2: "increased response in the range between 900kHz to 1350kHz"
FS_ACQ = 100e6  # §3.2: "sample rate of 100MHz"
FS_RECIPE = 6.75e6  # §3.2: "re-sampled to 5 times the maximum frequency ... 6.75MHz"
MA_SPAN = 100  # §3.2: "moving average filter, with a span of 100 points"
RECIPE_KEEP = {"thesis-chirp-100ms": 2000, "thesis-multisine": 2000, "thesis-chirp-1ms": 1000}

PROTOCOLS = {
    "thesis-chirp-100ms": "linear chirp 900-1350 kHz over 100 ms, 80 mVpp before the amplifier, 100 MHz "
    "(10 M samples); options duration, fs, preprocess, start, keep",
    "thesis-multisine": "45 000 random-phase lines 900-1350 kHz, 0.4 V peak, 10 MS/s file truncated to 5000 points "
    "and repeated, 100 MHz; options duration, fs, awg_rate_hz, warmup_s, preprocess, start, keep",
    "thesis-chirp-1ms": "1 ms linear up-chirp 900-1350 kHz, 150 mVpp, repeated (validation signal), 100 MHz; "
    "options duration, fs, warmup_s, preprocess, start, keep",
    "vna-sweep": "magnitude response |V_rx/V_oc| as a VNA measures it (Figure 3.9 analogue); options f_start, f_stop, "
    "points, gated, preprocess (multiplies by the recipe's filters)",
}


def excitation(
    protocol: str, fs: float = FS_ACQ, duration: float = 0.1, seed: int | None = 0, awg_rate_hz: float = 10e6
) -> tuple[np.ndarray, bool, dict]:
    """Input ``u`` [V, before the amplifier] of a time-domain protocol: (u, periodic, info)."""
    from sysid.signals import excitation as signals

    n = int(round(duration * fs))
    if n < 2:
        raise ConfigError(f"{protocol}: duration {duration} s gives fewer than 2 samples at {fs:g} Hz")
    if protocol == "thesis-chirp-100ms":
        # one 100 ms sweep; a shorter duration records the start of the same sweep (rate 4.5 kHz/ms unchanged)
        # sysid.signals.chirp(fs, 0.1, 900e3, 1350e3, amplitude=0.04) evaluated by the same expression, compiled
        # (the 10^7-sample record in ≈ 0.1 s) and only for the samples recorded; equality is tested
        full = int(round(0.1 * fs))
        u = chirp_prefix(fs, 0.1, BAND_HZ[0], BAND_HZ[1], 0.040, min(n, full))
        if n > full:  # the sweep ended before the record did
            u = np.concatenate([u, np.zeros(n - full)])
        return u[:n], False, {"sweep_s": 0.1, "vpp": 0.080}
    if protocol == "thesis-chirp-1ms":
        period = int(round(1e-3 * fs))
        one = signals.chirp(fs, 1e-3, BAND_HZ[0], BAND_HZ[1], amplitude=0.075, method="linear")
        reps = -(-n // period)
        return np.tile(one[:period], reps)[:n], True, {"sweep_s": 1e-3, "vpp": 0.150, "period_samples": period}
    if protocol == "thesis-multisine":
        from sysid.signals.preprocess import resample

        file_, info = signals.multisine(
            fs=awg_rate_hz,
            band=(BAND_HZ[0], BAND_HZ[1] - 10.0),
            components=45000,
            resolution=10.0,
            amplitude=0.4,
            phase="random",
            seed=seed,
            return_info=True,
        )
        piece = file_[:5000]
        period_s = piece.size / awg_rate_hz
        if abs(awg_rate_hz - fs) < 1e-6:
            one = piece
        else:
            # interpolate one repetition of the played piece, periodically (the generator loops it)
            one = resample(np.tile(piece, 3), awg_rate_hz, fs)
            m = int(round(period_s * fs))
            one = one[m : 2 * m]
        reps = -(-n // one.size)
        return (
            np.tile(one, reps)[:n],
            True,
            {
                "awg_rate_hz": awg_rate_hz,
                "file_points": int(file_.size),
                "played_points": 5000,
                "period_s": period_s,
                "crest_factor_file": float(info["crest_factor"]),
            },
        )
    raise ConfigError(f"{protocol} is not a time-domain protocol")


def chirp_prefix(fs: float, sweep_s: float, f0: float, f1: float, amplitude: float, n: int) -> np.ndarray:
    """First ``n`` samples of ``sysid.signals.chirp(fs, sweep_s, f0, f1, amplitude)`` (linear sweep, eq. 2-2):
    cycles(k) = f0 t + (f1 − f0) t²/(2 T0), t = k/fs — the same expression, evaluated on a prefix only."""
    t0 = int(round(sweep_s * fs)) / fs
    return _chirp_kernel(int(n), f0 / fs, (f1 - f0) / (2.0 * t0 * fs * fs), float(amplitude))


@njit(cache=True, parallel=True)
def _chirp_kernel(n, a, b, amplitude):  # pragma: no cover - compiled
    out = np.empty(n)
    for i in prange(n):
        k = float(i)
        c = k * a + (k * k) * b
        c -= np.floor(c)
        out[i] = amplitude * np.cos(2.0 * np.pi * c)
    return out


def recipe_steps() -> list[dict]:
    """The dissertation's preprocessing (§3.2) as :func:`sysid.signals.preprocess.apply_steps` steps (before
    truncation)."""
    return [
        {"step": "moving_average", "span": MA_SPAN},
        {"step": "resample", "fs_new": FS_RECIPE},
        {"step": "bandpass", "fmin": BAND_HZ[0], "fmax": BAND_HZ[1], "order": 5},
    ]


def apply_recipe(rec: Record, keep: int, start: int = 0) -> Record:
    """Moving average 100 → resample 6.75 MHz → band-pass 900–1350 kHz → truncate to ``keep`` from ``start``."""
    from sysid.signals.preprocess import apply_steps

    out = apply_steps(rec, recipe_steps())
    if start < 0 or keep < 1 or start + keep > len(out):
        raise ConfigError(f"truncation start={start}, keep={keep} exceeds the {len(out)} preprocessed samples")
    sliced = out[start : start + keep]
    sliced.meta.setdefault("preprocessing", []).append(
        {"step": "truncate", "params": {"start": start, "keep": keep}, "changes": {"n_before": len(out)}}
    )
    return sliced
