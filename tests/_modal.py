"""Lightly damped multi-mode linear systems for the order-choice and FIR tests (a structure's force → acceleration,
as in a ground-vibration test): a sum of second-order modes, each ω_k² g_k s²/(s² + 2ζ_k ω_k s + ω_k²) scaled to a
static gain g_k / ω_k², discretised by the bilinear (Tustin) map, so every mode has a direct feed-through."""

from __future__ import annotations

import numpy as np
from scipy import signal

from sysid.data.record import Record
from sysid.signals.excitation import multisine

FREQS_HZ = (23.0, 51.0, 88.0, 140.0, 210.0)
ZETAS = (0.005, 0.008, 0.01, 0.015, 0.02)


def modal_filters(fs: float, freqs=FREQS_HZ, zetas=ZETAS, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """(b, a) per mode; gains uniform in [0.5, 1.5] with random signs (seeded)."""
    rng = np.random.default_rng(seed)
    out = []
    for f, z in zip(freqs, zetas):
        w = 2 * np.pi * f
        g = rng.uniform(0.5, 1.5) * (1.0 if rng.random() > 0.3 else -1.0)
        b, a = signal.bilinear([g, 0.0, 0.0], [1.0, 2 * z * w, w * w], fs)
        out.append((np.ravel(b), np.ravel(a)))
    return out


def time_constant_samples(fs: float, freqs=FREQS_HZ, zetas=ZETAS) -> float:
    """Slowest modal decay time 1/(ζω) in samples: the impulse response's memory scale."""
    return max(fs / (z * 2 * np.pi * f) for f, z in zip(freqs, zetas))


def modal_records(
    n: int = 8192, fs: float = 1000.0, noise: float = 0.01, band=(3.0, 300.0), seed: int = 0, levels=(0.2, 1.0), **kw
) -> list[Record]:
    """Estimation (low level) and validation (higher level) records of ``n`` samples: random-phase multisines in
    ``band`` (one period simulated before the kept one, so the transient is gone), output noise of ``noise`` × the
    output's standard deviation."""
    modes = modal_filters(fs, seed=seed, **kw)
    rng = np.random.default_rng(seed + 1)
    out = []
    for k, level in enumerate(levels):
        u = multisine(fs, duration=2 * n / fs, band=band, amplitude=level, rms=True, seed=seed + 10 + k, periods=2)
        y0 = sum(signal.lfilter(b, a, u) for b, a in modes)[n:]
        y = y0 + noise * np.std(y0) * rng.standard_normal(n)
        out.append(Record(u[n:], y, fs=fs, units={"u": "N", "y": "m/s2"}))
    return out


def write_modal_pair(folder, n: int) -> tuple[str, str]:
    """The estimation and validation records of :func:`modal_records` written to ``folder`` (est.npz, val.npz):
    the paths, for the tests that run ``piezotwin identify`` on them."""
    from pathlib import Path

    from sysid.data.io import write_record

    est, val = modal_records(n=n)
    paths = (str(Path(folder) / "est.npz"), str(Path(folder) / "val.npz"))
    write_record(est, paths[0])
    write_record(val, paths[1])
    return paths
