"""Frequency-domain residual features: residual power in and out of the excited band, intermodulation bands,
harmonics of a sine, detection lines of a multisine, nonlinear correlations and narrow resonance peaks.

Every function takes plain arrays and an explicit sampling rate ``fs`` [Hz] and returns numbers.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import signal as sps

from .timing import _z

__all__ = [
    "excited_band",
    "band_powers",
    "product_bands",
    "harmonics",
    "odd_even_lines",
    "nonlinear_correlation",
    "resonance_peaks",
]


def _psd(x: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    n = len(x)
    nper = int(min(n, max(256, 1 << int(np.log2(max(n // 8, 2))))))
    return sps.welch(np.asarray(x, dtype=float), fs=fs, nperseg=nper)


def excited_band(u: np.ndarray, fs: float, rel_db: float = -30.0) -> tuple[float, float]:
    """Frequency range [Hz] where the input's PSD lies within ``rel_db`` of its maximum."""
    f, p = _psd(u, fs)
    if not np.any(p > 0):
        return (0.0, 0.0)
    on = p >= p.max() * 10 ** (rel_db / 10)
    idx = np.flatnonzero(on)
    return float(f[idx[0]]), float(f[idx[-1]])


def band_powers(e: np.ndarray, u: np.ndarray, y: np.ndarray, fs: float) -> dict[str, float]:
    """Residual power inside and outside the excited band, absolute and relative to the output's power there.

    ``in_band_db`` / ``out_band_db``: 10·log10 of residual power ÷ output power in that band (how much of the
    output the simulation misses there); ``out_minus_in_db``: how much stronger the out-of-band residual is
    per Hz than the in-band one (distortion products and unmodelled resonances raise it).
    """
    f0, f1 = excited_band(u, fs)
    f, pe = _psd(e, fs)
    _, py = _psd(y, fs)
    inside = (f >= f0) & (f <= f1)
    outside = ~inside & (f > 0)
    pin = float(np.sum(pe[inside])) or 1e-300
    pout = float(np.sum(pe[outside])) or 1e-300
    yin = float(np.sum(py[inside])) or 1e-300
    yout = float(np.sum(py[outside])) or 1e-300
    dens_in = pin / max(inside.sum(), 1)
    dens_out = pout / max(outside.sum(), 1)
    return {
        "band_hz": [f0, f1],
        "in_band_db": 10 * np.log10(pin / yin),
        "out_band_db": 10 * np.log10(pout / yout),
        "out_minus_in_db": float(10 * np.log10(dens_out / dens_in)),
        "in_share": pin / (pin + pout),
    }


def product_bands(e: np.ndarray, u: np.ndarray, fs: float) -> dict[str, Any]:
    """Where the residual's power lies relative to the intermodulation bands of a band-pass input.

    For an input exciting [f₀, f₁] with f₁ < 2f₀ (less than an octave), second-order (even) products fall in
    the difference band (0, f₁−f₀] and the sum band [2f₀, 2f₁] — both outside the excited band — while
    third-order (odd) products fall in the excited band and its skirts [2f₀−f₁, f₀) ∪ (f₁, 2f₁−f₀]. Mean
    residual PSD densities are compared in dB with the quietest of these bands (the floor): ``even_db`` (the
    larger of the difference and sum band), ``in_db`` (the excited band) and ``skirt_db``. An even-order
    distortion raises ``even_db`` alone; an odd one or a linear error raises ``in_db``. ``valid`` is False for
    an input wider than an octave or bands that the sampling rate cannot hold.
    """
    f0, f1 = excited_band(u, fs)
    nyq = fs / 2.0
    if not (0 < f0 < f1 < 2 * f0) or 2 * f0 >= 0.98 * nyq:
        return {"valid": False, "even_db": 0.0, "in_db": 0.0, "skirt_db": 0.0}
    f, p = _psd(e, fs)
    b = f1 - f0
    guard = 0.02 * b

    def dens(lo: float, hi: float) -> float:
        sel = (f >= lo) & (f <= hi)
        return float(np.mean(p[sel])) if sel.sum() >= 2 else float("nan")

    bands: dict[str, float] = {
        "in": dens(f0 + guard, f1 - guard),
        "diff": dens(max(0.05 * b, f[1] if f.size > 1 else 0.0), b - guard),
        "sum": dens(2 * f0 + guard, min(2 * f1, 0.98 * nyq)),
        "skirt": float(
            np.nanmean([dens(2 * f0 - f1 + guard, f0 - guard), dens(f1 + guard, min(2 * f1 - f0, 2 * f0) - guard)])
        ),
    }
    vals = [v for v in bands.values() if np.isfinite(v) and v > 0]
    if len(vals) < 3:
        return {"valid": False, "even_db": 0.0, "in_db": 0.0, "skirt_db": 0.0}
    floor = min(vals)
    db = {k: (float(10 * np.log10(v / floor)) if np.isfinite(v) and v > 0 else 0.0) for k, v in bands.items()}
    return {
        "valid": True,
        "band_hz": [f0, f1],
        "even_db": max(db["diff"], db["sum"]),
        "diff_db": db["diff"],
        "sum_db": db["sum"],
        "in_db": db["in"],
        "skirt_db": db["skirt"],
    }


def harmonics(e: np.ndarray, u: np.ndarray, fs: float, n_harm: int = 5) -> dict[str, Any]:
    """Residual amplitude at the harmonics 2f…n·f of a (near-)sinusoidal input of fundamental f.

    Returns the fundamental, per-harmonic amplitudes and ``odd_over_even_db`` (power at 3f, 5f, … over 2f,
    4f, …): positive for odd-order (symmetric) distortion, negative for even-order (asymmetric).
    """
    u = np.asarray(u, dtype=float)
    n = u.size
    win = np.hanning(n)
    U = np.abs(np.fft.rfft((u - u.mean()) * win))
    E = np.abs(np.fft.rfft((np.asarray(e) - np.mean(e)) * win))
    freqs = np.fft.rfftfreq(n, 1 / fs)
    if U.size < 4:
        return {"f0_hz": float("nan"), "amplitudes": [], "odd_over_even_db": 0.0}
    k0 = int(np.argmax(U[1:])) + 1
    sine_like = U[k0] ** 2 / max(float(np.sum(U**2)), 1e-300)
    amps = []
    for h in range(1, n_harm + 1):
        k = h * k0
        if k + 2 >= E.size:
            break
        amps.append(float(np.max(E[max(k - 2, 0) : k + 3])) * 2 / win.sum())
    odd = sum(a**2 for i, a in enumerate(amps, 1) if i % 2 == 1 and i > 1)
    even = sum(a**2 for i, a in enumerate(amps, 1) if i % 2 == 0)
    return {
        "f0_hz": float(freqs[k0]),
        "sine_share": float(sine_like),
        "amplitudes": amps,
        "odd_over_even_db": float(10 * np.log10((odd + 1e-300) / (even + 1e-300))),
    }


def odd_even_lines(
    u: np.ndarray, y: np.ndarray, e: np.ndarray, fs: float, period: int | None = None, rel_db: float = -40.0
) -> dict[str, Any]:
    """Power on the excited, odd non-excited (detection) and even lines of a periodic multisine.

    The record (or its first whole number of periods of length ``period`` samples, averaged) is transformed;
    excited lines are those where the input's power is within ``rel_db`` of its maximum. Lines are indexed in
    units of the frequency resolution; with an odd multisine the excited lines are odd, so the non-excited
    odd lines inside the band collect odd-order distortion and the even lines even-order distortion.
    Powers are given for the measured output and for the residual, in dB relative to the mean excited-line
    power of y. ``odd_minus_even_db`` > 0 means odd-order distortion dominates.
    """
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    e = np.asarray(e, dtype=float)
    P = int(period) if period else u.size
    nper = u.size // P if P <= u.size else 0
    if nper < 1:
        return {"valid": False}

    def avg(x):
        return np.fft.rfft(x[: nper * P].reshape(nper, P).mean(axis=0))

    U, Y, E = avg(u), avg(y), avg(e)
    pu = np.abs(U) ** 2
    pu[0] = 0
    exc = pu >= pu.max() * 10 ** (rel_db / 10)
    ex_idx = np.flatnonzero(exc)
    if ex_idx.size < 3:
        return {"valid": False}
    # base grid: gcd of the excited lines
    g = int(np.gcd.reduce(ex_idx))
    lines = np.arange(U.size)
    on_grid = (lines % g == 0) & (lines > 0)
    m = lines // max(g, 1)
    lo, hi = ex_idx[0], ex_idx[-1]
    band = (lines >= lo) & (lines <= hi) & on_grid & ~exc
    odd_det = band & (m % 2 == 1)
    even_det = band & (m % 2 == 0)
    odd_grid = bool(np.all((ex_idx // g) % 2 == 1))
    ref = float(np.mean(np.abs(Y[exc]) ** 2)) or 1e-300

    def lvl(X, mask):
        return float(10 * np.log10((np.mean(np.abs(X[mask]) ** 2) if mask.any() else 0.0) / ref + 1e-30))

    out = {
        "valid": True,
        "odd_grid": odd_grid,
        "n_excited": int(exc.sum()),
        "n_odd_detection": int(odd_det.sum()),
        "n_even": int(even_det.sum()),
        "y_odd_db": lvl(Y, odd_det),
        "y_even_db": lvl(Y, even_det),
        "e_odd_db": lvl(E, odd_det),
        "e_even_db": lvl(E, even_det),
        "e_excited_db": lvl(E, exc),
    }
    out["odd_minus_even_db"] = (out["e_odd_db"] - out["e_even_db"]) if (odd_det.any() and even_det.any()) else 0.0
    return out


def _orth(x: np.ndarray, basis: list[np.ndarray]) -> np.ndarray:
    A = np.column_stack([np.ones_like(x)] + basis)
    c, *_ = np.linalg.lstsq(A, x, rcond=None)
    return x - A @ c


def nonlinear_correlation(e: np.ndarray, u: np.ndarray, ysim: np.ndarray, max_lag: int = 20) -> dict[str, float]:
    """Largest |cross-correlation| over lags 0…max_lag of the residual with the nonlinear parts of u and ŷ.

    ``u2`` / ``u3``: (u²)′ and (u³)′ made orthogonal to 1 and u (and u² for u³), the even and odd static
    nonlinearity of the input; ``y2`` / ``y3`` the same for the simulated output; ``lin`` the linear
    correlation with u. A symmetric (odd) compression correlates with the cubic part, an asymmetric
    (even) one with the square. Values are correlation coefficients; ``band`` is the 95 % white band 1.96/√N.
    """
    e = _z(e)
    n = e.size
    out = {"band": 1.96 / np.sqrt(n)}
    for name, x in (("u", _z(u)), ("y", _z(ysim))):
        x2 = _z(_orth(x**2, [x]))
        x3 = _z(_orth(x**3, [x, x**2]))
        for tag, s in (("lin", x), ("2", x2), ("3", x3)):
            m = 1 << int(np.ceil(np.log2(2 * n)))
            xc = np.fft.irfft(np.fft.rfft(e, m) * np.conj(np.fft.rfft(s, m)), m)
            vals = np.r_[xc[: max_lag + 1], xc[m - max_lag :]] / n
            key = f"{name}{tag}" if tag != "lin" else f"{name}_lin"
            out[key] = float(np.max(np.abs(vals)))
    return out


def resonance_peaks(
    e: np.ndarray, y: np.ndarray, fs: float, min_db: float = 10.0, max_peaks: int = 3
) -> list[dict[str, float]]:
    """Narrow peaks of the residual PSD that rise ``min_db`` above its running median (unmodelled modes).

    Each peak: frequency [Hz], prominence [dB] above the local median, and residual-to-output power ratio
    at that frequency [dB] (near 0 dB: the simulation misses the output there entirely).
    """
    f, pe = _psd(e, fs)
    _, py = _psd(y, fs)
    if pe.size < 16:
        return []
    lp = 10 * np.log10(pe + 1e-300)
    k = max(5, (pe.size // 20) | 1)
    med = sps.medfilt(lp, k)
    prom = lp - med
    idx, _ = sps.find_peaks(prom, height=min_db)
    idx = idx[np.argsort(prom[idx])[::-1]][:max_peaks]
    return [
        {
            "freq_hz": float(f[i]),
            "prominence_db": float(prom[i]),
            "residual_over_output_db": float(10 * np.log10((pe[i] + 1e-300) / (py[i] + 1e-300))),
        }
        for i in idx
    ]
