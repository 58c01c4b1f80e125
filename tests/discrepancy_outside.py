"""Acoustic hidden-effect cases injected by code outside the twin, on its bare simulation.

The data are the compression-, noise- and ADC-free twin's simulation ("bare": no catalog effect on) with an
effect written here in a few lines — a tanh limiter, a cubic soft clip or a hard clip of the generator
signal, an in-phase copy of the drive (a resistive crosstalk path, 10 % of the estimation output's RMS), a
delayed scaled copy of the output (an echo: 0.1–0.3 of it, 8–25 µs later, linear interpolation between
samples; ``echo_lp``: the same copy through a first-order Butterworth low-pass at 0.5–2 MHz, a lossy wall) — and
white noise of 1 % of the output RMS. Records as in :mod:`discrepancy_cases`: the 2 ms, 5 MHz
multisine for estimation and the 1 ms chirp at the multisine's 0.4 V peak for validation. The twin diagnosed
is the bare configuration.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq
from scipy.signal import butter, lfilter

from sysid.data.record import Record

FS = 5e6
KINDS = ("tanh", "cubic", "clip", "inphase", "echo", "echo_lp", "none")


def _limiter(kind: str, peak: float, compression: float):
    """A limiter of the generator signal that compresses its peak ``peak`` by ``compression`` (a fraction)."""
    target = (1.0 - compression) * peak
    if kind == "tanh":
        a = brentq(lambda a: a * np.tanh(peak / a) - target, 1e-3 * peak, 1e3 * peak)
        return lambda u: a * np.tanh(u / a)
    if kind == "cubic":  # v − v³/(3 v0²), flat beyond its turning point v0 (compression ≤ 1/3 at v0)
        v0 = brentq(lambda v0: peak - peak**3 / (3 * v0 * v0) - target, peak, 1e3 * peak)
        return lambda u: np.clip(u, -v0, v0) - np.clip(u, -v0, v0) ** 3 / (3 * v0 * v0)
    if kind == "clip":
        return lambda u: np.clip(u, -target, target)
    raise ValueError(kind)


def outside_case(kind: str, seed: int, level: float | None = None, start_effects: str | None = "none"):
    """(start twin, est, val, truth) for one case; ``truth`` holds the injected size. ``level``: the compression
    at the peak (drawn in 10–25 %, cubic 10–30 %) or the crosstalk share of the output RMS (default 10 %).
    ``start_effects``: the effects of the twin diagnosed (``"none"``: bare; None: the default configuration,
    whose Rapp compression at 105 V is then re-tested rather than added)."""
    from twins.acoustic import AcousticTwin

    rng = np.random.default_rng(4242 + seed)
    bare_e = AcousticTwin.from_options(effects="none", seed=seed)
    ue = AcousticTwin.from_options(seed=seed).generate("thesis-multisine", fs=FS, duration=2e-3, warmup_s=0.0).u
    ch = bare_e.generate("thesis-chirp-1ms", fs=FS, duration=2e-3, warmup_s=0.0)
    uv = ch.u * (0.4 / np.max(np.abs(ch.u)))
    peak = float(np.max(np.abs(ue)))
    truth: dict[str, float | str] = {"kind": kind}
    if kind in ("tanh", "cubic", "clip"):
        comp = float(level if level is not None else rng.uniform(0.10, 0.30 if kind == "cubic" else 0.25))
        lim = _limiter(kind, peak, comp)
        truth["compression_at_peak"] = comp
    else:
        lim = None
    share = float(level if level is not None else 0.10) if kind == "inphase" else 0.0
    if share:
        truth["crosstalk_share"] = share
    if kind in ("echo", "echo_lp"):
        truth["echo_amplitude"] = float(level if level is not None else rng.uniform(0.1, 0.3))
        truth["echo_delay_s"] = float(rng.uniform(8e-6, 25e-6))
    if kind == "echo_lp":
        truth["echo_cutoff_hz"] = float(rng.uniform(0.5e6, 2e6))
    out = []
    coupling = 0.0
    for u in (ue, uv):
        y = bare_e.simulate(lim(u) if lim is not None else u, FS)
        if share:  # one coupling coefficient for both records: share × the estimation output's RMS
            coupling = coupling or share * np.sqrt(np.mean(y**2)) / np.sqrt(np.mean(u**2))
            y = y + coupling * u
        if kind in ("echo", "echo_lp"):
            n = np.arange(y.size)
            copy = np.interp(n - float(truth["echo_delay_s"]) * FS, n, y, left=0.0)
            if kind == "echo_lp":
                copy = lfilter(*butter(1, float(truth["echo_cutoff_hz"]), fs=FS), copy)
            y = y + float(truth["echo_amplitude"]) * copy
        y = y + 0.01 * np.sqrt(np.mean(y**2)) * rng.standard_normal(y.size)
        out.append(Record(u=u, y=y, fs=FS, meta={"injected": dict(truth)}))
    start = AcousticTwin.from_options(effects=start_effects, seed=0)
    return start, out[0], out[1], truth


def expected_effect(kind: str) -> str | None:
    return {
        "tanh": "amplifier_compression",
        "cubic": "amplifier_compression",
        "clip": "amplifier_compression",
        "inphase": "crosstalk",
        "echo": "wall_echo",
        "echo_lp": "wall_echo",
    }.get(kind)
