"""Per-sample core for twins simulated in the frequency domain (the 100 MHz acoustic channel).

The twin's block simulation is ``y = measure(h * amplifier(u))`` with the linear chain given as a complex
frequency response ``H(f)`` (``twin.frequency_response(f_hz)``, echoes included as configured). An FMU
advances one sample per communication step, so the core here realises ``H`` as a causal **sparse FIR**:

1. ``h[n] = irfft(H(k fs / N))`` on a grid long enough that the last eighth of ``h`` holds less than
   ``tail_tol`` of its energy (``N`` doubles from 2^15 up to 2^22); this is the impulse response the
   native FFT simulation convolves with, up to the time aliasing that the tail test bounds.
2. ``h`` is cut into blocks of ``block`` samples; the weakest blocks are dropped while the dropped energy
   stays below ``energy_tol`` of the total (so the silent time of flight before the first arrival and the
   gaps between echoes cost nothing); the kept blocks are merged into segments when the gap between them
   is shorter than ``merge_gap`` samples (one numpy dot per segment costs about as much as ~1000 taps).
3. Per sample: the amplifier output is written into a mirrored ring buffer (newest first, contiguous
   window) and each segment adds ``dot(taps, window[start:start+len])``.

For a white input the relative RMS error of the truncation is ``sqrt(dropped energy / total energy)``;
the export measures the actual error against ``twin.simulate`` on a chirp and stores it in the FMU.
Measurement noise and ADC (``twin.measure``) are applied per sample with the twin's seeded generator.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["impulse_response", "sparse_segments", "fir_apply", "ResponseCore", "prepare_response_core"]

DEFAULTS = {"tail_tol": 1e-12, "energy_tol": 1e-10, "block": 32, "merge_gap": 1024}


def impulse_response(twin, fs: float, tail_tol: float = DEFAULTS["tail_tol"], n_min: int = 2 ** 15,
                     n_max: int = 2 ** 22) -> np.ndarray:
    """Real impulse response of ``twin.frequency_response`` sampled at ``fs`` [Hz] (length a power of 2)."""
    n = n_min
    while True:
        f = np.fft.rfftfreq(n, 1.0 / fs)
        H = np.asarray(twin.frequency_response(f), dtype=complex)
        h = np.fft.irfft(H, n)
        e = h * h
        total = float(e.sum())
        if total == 0.0:
            return h
        if float(e[-n // 8:].sum()) <= tail_tol * total or n >= n_max:
            return h
        n *= 2


def sparse_segments(h: np.ndarray, energy_tol: float = DEFAULTS["energy_tol"], block: int = DEFAULTS["block"],
                    merge_gap: int = DEFAULTS["merge_gap"]) -> tuple[list[tuple[int, np.ndarray]], float]:
    """Segments ``[(start, taps), ...]`` of ``h`` keeping all but ``energy_tol`` of its energy.

    Returns the segments and the dropped fraction of the energy.
    """
    h = np.asarray(h, dtype=float)
    n_blocks = -(-len(h) // block)
    padded = np.zeros(n_blocks * block)
    padded[:len(h)] = h
    be = (padded.reshape(n_blocks, block) ** 2).sum(axis=1)
    total = float(be.sum())
    if total == 0.0:
        return [], 0.0
    order = np.argsort(be)
    dropped = np.cumsum(be[order]) / total
    n_drop = int(np.searchsorted(dropped, energy_tol, side="right"))
    keep = np.ones(n_blocks, dtype=bool)
    keep[order[:n_drop]] = False
    idx = np.flatnonzero(keep)
    segments: list[tuple[int, int]] = []
    for b in idx:
        s, e = b * block, (b + 1) * block
        if segments and s - segments[-1][1] <= merge_gap:
            segments[-1] = (segments[-1][0], e)
        else:
            segments.append((s, e))
    out = [(s, padded[s:e].copy()) for s, e in segments]
    kept = sum(float((t ** 2).sum()) for _, t in out)
    return out, max(0.0, 1.0 - kept / total)


def fir_apply(segments: list[tuple[int, np.ndarray]], x: np.ndarray) -> np.ndarray:
    """Vectorised equivalent of the per-sample core's linear part (causal, zero initial state)."""
    from scipy.signal import oaconvolve

    x = np.asarray(x, dtype=float)
    y = np.zeros(len(x))
    for start, taps in segments:
        if start >= len(x):
            continue
        part = oaconvolve(x, taps)[: len(x) - start]
        y[start:] += part
    return y


class ResponseCore:
    """``step(u) -> y``: amplifier, sparse FIR of ``H``, measurement (noise + ADC), one sample at a time."""

    def __init__(self, segments, amplifier, measure=None, fs: float = 1.0, seed: int | None = 0):
        self.segments = [(int(s), np.ascontiguousarray(t, dtype=float)) for s, t in segments]
        self.length = max([s + len(t) for s, t in self.segments] or [1])
        self.amplifier = amplifier
        self.measure = measure
        self.fs = float(fs)
        self.seed = seed
        self.reset()

    @classmethod
    def for_twin(cls, twin, fs: float, core: dict[str, Any], resources: str | Path | None = None) -> "ResponseCore":
        """The core of ``twin`` at ``fs``: the taps baked at export when the twin's linear chain is
        unchanged, else a fresh impulse response from ``twin.frequency_response``."""
        segments = None
        if resources is not None and core.get("file") and core.get("linear_key") == linear_key(twin, fs):
            data = np.load(Path(resources) / core["file"], allow_pickle=False)
            starts = data["starts"]
            bounds = data["bounds"]
            taps = data["taps"]
            segments = [(int(starts[i]), taps[bounds[i]:bounds[i + 1]]) for i in range(len(starts))]
        if segments is None:
            opts = {k: core.get(k, v) for k, v in DEFAULTS.items()}
            h = impulse_response(twin, fs, opts["tail_tol"])
            segments, _ = sparse_segments(h, opts["energy_tol"], opts["block"], opts["merge_gap"])
        return cls(segments, amplifier_of(twin), measure_of(twin, fs), fs, twin.seed)

    def reset(self) -> None:
        self.buf = np.zeros(2 * self.length)
        self.pos = 0
        self.rng = np.random.default_rng(self.seed)
        self._u = None
        self._a = 0.0

    def step(self, u: float) -> float:
        if u != self._u:  # the amplifier is memoryless; inputs are held over a communication step
            self._u = u
            self._a = float(self.amplifier(u))
        L = self.length
        p = self.pos - 1
        if p < 0:
            p += L
        self.pos = p
        buf = self.buf
        buf[p] = self._a
        buf[p + L] = self._a
        y = 0.0
        for start, taps in self.segments:
            a = p + start
            y += float(np.dot(taps, buf[a:a + len(taps)]))
        if self.measure is not None:
            y = float(self.measure(y, self.rng))
        return y


def linear_key(twin, fs: float) -> str:
    """Identifies what the taps depend on (the whole configuration, seed excluded, and fs)."""
    import json

    from twins.base import _json_default

    cfg = twin.config()
    cfg.pop("seed", None)
    return json.dumps({"cfg": cfg, "fs": float(fs)}, sort_keys=True, default=_json_default)


def amplifier_of(twin):
    """``twin.amplifier`` as a float -> float function (identity when the twin has none).

    Calls it on a Python float when that gives the same value as on a one-element array (numpy ufunc
    code does, ~1 us), else on a one-element array."""
    amp = getattr(twin, "amplifier", None)
    if amp is None:
        return lambda x: x
    probe = np.array([-1e3, -3.0, -0.1, 0.0, 0.2, 4.0, 1e3])
    try:
        ref = np.asarray(amp(probe), dtype=float)
        scalar = np.array([float(np.asarray(amp(float(v)), dtype=float).reshape(-1)[0]) for v in probe])
        if np.array_equal(ref, scalar):
            return amp
    except Exception:  # the twin's amplifier wants arrays
        pass
    one = np.zeros(1)

    def on_array(x: float) -> float:
        one[0] = x
        return np.asarray(amp(one), dtype=float)[0]

    return on_array


def measure_of(twin, fs: float):
    """Per-sample ``(y, rng) -> y`` from ``twin.measure(y, fs, rng)`` (noise + ADC), or None.

    ``measure`` is called on one-element arrays with the core's generator, so a twin whose ``measure``
    draws one value per sample in order (e.g. ``rng.standard_normal(y.shape)``) gets exactly the noise of
    its block ``simulate``: numpy Generators give the same stream drawn one by one or at once.
    """
    fn = getattr(twin, "measure", None)
    if fn is None:
        return None
    one = np.zeros(1)

    def measure(y: float, rng) -> float:
        one[0] = y
        return np.asarray(fn(one, fs, rng), dtype=float).reshape(-1)[0]

    return measure


def prepare_response_core(twin, fs: float, core: dict[str, Any], stage: Path, filename: str,
                          check_seconds: float = 2e-4) -> dict[str, Any]:
    """Compute the taps at export, write them to ``stage/filename`` and measure the accuracy."""
    opts = {k: core.get(k, v) for k, v in DEFAULTS.items()}
    h = impulse_response(twin, fs, opts["tail_tol"])
    segments, dropped = sparse_segments(h, opts["energy_tol"], opts["block"], opts["merge_gap"])
    starts = np.array([s for s, _ in segments], dtype=np.int64)
    lengths = [len(t) for _, t in segments]
    bounds = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    taps = np.concatenate([t for _, t in segments]) if segments else np.zeros(0)
    np.savez_compressed(Path(stage) / filename, starts=starts, bounds=bounds, taps=taps)
    accuracy = check_accuracy(twin, fs, segments, h, min_seconds=check_seconds)
    accuracy["dropped_energy"] = dropped
    out = dict(core)
    out.update(opts)
    out.update({"file": filename, "linear_key": linear_key(twin, fs), "impulse_length": len(h),
                "segments": [[int(s), int(n)] for s, n in zip(starts, lengths)], "n_taps": int(len(taps)),
                "dropped_energy": dropped, "accuracy": accuracy})
    return out


def check_chirp(twin, fs: float, h: np.ndarray, n: int) -> tuple[np.ndarray, str]:
    """A linear chirp of ``n`` samples, 1 V, over 0.3 .. 3 times the peak of ``|H|``."""
    H = np.abs(np.fft.rfft(h))
    f_peak = float(np.fft.rfftfreq(len(h), 1.0 / fs)[int(np.argmax(H))]) or fs / 100
    f0, f1 = 0.3 * f_peak, min(3.0 * f_peak, 0.45 * fs)
    t = np.arange(n) / fs
    T = n / fs
    u = np.sin(2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / T * t * t))
    return u, f"linear chirp 1 V {f0:.4g}-{f1:.4g} Hz, {n} samples"


def check_accuracy(twin, fs: float, segments, h: np.ndarray, u: np.ndarray | None = None,
                   min_seconds: float = 2e-4) -> dict[str, Any]:
    """Relative RMS of the core's output (vectorised, noise-free) against the noise-free ``simulate``."""
    from twins.fmu.check import relative_rms

    quiet = twin.with_effects(set(twin.effects) - {"measurement_noise"})
    length = max([s + len(t) for s, t in segments] or [1])
    if u is None:
        u, what = check_chirp(twin, fs, h, int(max(min_seconds * fs, 1.2 * length)))
    else:
        what = f"given input, {len(u)} samples"
    ref = np.asarray(quiet.simulate(u, fs), dtype=float)
    y = fir_apply(segments, np.asarray(quiet.amplifier(u), dtype=float) if hasattr(quiet, "amplifier") else u)
    if hasattr(quiet, "measure"):
        y = np.asarray(quiet.measure(y, fs, np.random.default_rng(quiet.seed)), dtype=float)
    return {"signal": what, "relative_rms": relative_rms(y, ref),
            "max_abs_error": float(np.max(np.abs(y - ref))), "rms_ref": float(np.sqrt(np.mean(ref ** 2)))}
