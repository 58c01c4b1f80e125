"""RF power amplifier (E&I 2100L class) as a Thevenin source with a memoryless nonlinearity (physics notes B.9).

- Gain G_v = 10^(gain_db/20) (50 dB is specified into a matched 50 Ω load), output resistance R_s = 50 Ω,
  so the open-circuit voltage is V_oc = 2·G_v·x for a linear amplifier. The load (the transmitter's Z_el)
  divides it; that division is part of the linear chain H(f) = V_rx/V_oc.
- Compression (odd, AM/AM) acts on the matched-load voltage v = G_v·x:
  * Rapp (1991): v_c = v / (1 + |v/A_sat|^{2p})^{1/(2p)}; saturates at A_sat (≈ 100–110 V peak into 50 Ω).
  * cubic soft clipper: v_c = v − v³/(3 v0²) for |v| ≤ v0, ±(2/3) v0 beyond, with v0 = 1.5·A_sat so that it
    also saturates at A_sat. For one tone of amplitude a (< v0): fundamental a − a³/(4 v0²), third harmonic
    a³/(12 v0²) (the general rule 3rd = a3·a³/4 with a3 = −1/(3v0²)).
  Both are odd functions of v: they produce odd harmonics only.
- The compression is a *family*, not one curve: the Rapp curve's smoothness p spans the shapes an
  amplifier's limiter takes, from tanh-like (p ≈ 1.2–1.4) through a cubic soft clip up to its turning point
  (p ≈ 1.5–1.8, sat ≈ 0.77 v0) to a hard clip (p → 64: ``|v| > A`` gives exactly ±A where |v/A|^{2p}
  overflows); each is matched within 1 % of its RMS (tests/test_amplifier_family.py). An optional asymmetry
  a (``asymmetry``, default 0 = odd) sets the saturation to A(1 + a) for v > 0 and A(1 − a) for v < 0 (a
  push-pull stage whose halves saturate at different levels): the curve stays monotone and continuous, and
  adds even harmonics.
- Optional even-order term (push-pull imbalance): v_c + k2·v_c²/A_sat; a tone of amplitude a gives
  k2·a²/(2 A_sat) at 2f (and the same at DC, removed by the AC-coupled chain).
- Bandwidth (≈ 10 kHz – 12 MHz): first-order high-pass and low-pass, applied in the frequency domain as a
  factor of the linear chain (the nonlinearity is memoryless; the out-of-band filtering after it differs from a
  Wiener–Hammerstein placement only outside 10 kHz–12 MHz).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["amplifier_voltage", "amplifier_bandwidth", "sample_amplifier", "voltage_gain"]


def voltage_gain(gain_db: float) -> float:
    """G_v = 10^(gain_db/20) (matched-load voltage gain)."""
    return float(10.0 ** (gain_db / 20.0))


def amplifier_voltage(
    x: np.ndarray,
    gain_db: float = 50.0,
    compression: str | None = None,
    sat_v: float = 105.0,
    smoothness: float = 2.5,
    even_ratio: float = 0.0,
    asymmetry: float = 0.0,
) -> np.ndarray:
    """Open-circuit output voltage V_oc [V] of the amplifier for the input ``x`` [V] (memoryless).

    ``compression``: None (linear), ``"rapp"`` or ``"cubic"``; ``sat_v``: output saturation A_sat [V peak into
    50 Ω]; ``smoothness``: Rapp p; ``even_ratio``: k2 of the even-order term (0 = none); ``asymmetry``: a,
    saturation A(1 ± a) for positive / negative v (0 = odd).
    """
    if compression == "rapp":
        return _rapp_kernel(
            np.ascontiguousarray(x, dtype=np.float64),
            voltage_gain(gain_db),
            float(sat_v),
            float(smoothness),
            float(even_ratio),
            float(asymmetry),
        )
    v = voltage_gain(gain_db) * np.asarray(x, dtype=float)
    if compression == "cubic":
        v0: float | np.ndarray = 1.5 * sat_v
        if asymmetry:
            v0 = np.where(v > 0, 1.5 * sat_v * (1.0 + asymmetry), 1.5 * sat_v * (1.0 - asymmetry))
        vc = np.clip(v, -v0, v0)
        v = vc - vc**3 / (3.0 * v0 * v0)
    elif compression not in (None, "none", "linear"):
        raise ValueError(f"unknown compression model {compression!r}")
    if even_ratio:
        v = v + even_ratio * v * v / sat_v
    return 2.0 * v


def sample_amplifier(
    gain_db: float = 50.0,
    compression: str | None = None,
    sat_v: float = 105.0,
    smoothness: float = 2.5,
    even_ratio: float = 0.0,
    asymmetry: float = 0.0,
):
    """``float -> float``: :func:`amplifier_voltage` for one sample at a time with the same arithmetic (the
    per-sample path of an FMU step: no array, no thread launch), or None for a compression without one."""
    gain, sat, k2, asym = voltage_gain(gain_db), float(sat_v), float(even_ratio), float(asymmetry)
    if compression == "rapp":
        p = float(smoothness)
        return lambda x: _rapp_scalar(float(x), gain, sat, p, k2, asym)
    if compression not in (None, "none", "linear"):
        return None

    def linear(x: float) -> float:
        v = gain * float(x)
        if k2:
            v = v + k2 * v * v / sat
        return 2.0 * v

    return linear


def amplifier_bandwidth(f_hz: np.ndarray, f_low_hz: float, f_high_hz: float) -> np.ndarray:
    """First-order high-pass (f_low) × first-order low-pass (f_high) response of the amplifier."""
    jf = 1j * np.asarray(f_hz, dtype=float)
    hp = (jf / f_low_hz) / (1.0 + jf / f_low_hz) if f_low_hz > 0 else 1.0
    lp = 1.0 / (1.0 + jf / f_high_hz) if np.isfinite(f_high_hz) else 1.0
    return np.asarray(hp * lp)


#: below this many samples the serial kernel runs (per-sample FMU steps: a parallel launch per sample costs
#: ~100 µs with both cores busy, the arithmetic well under 1 µs)
PARALLEL_MIN = 16384


@njit(cache=True, inline="always")
def _rapp_one(x, gain, sat, p2, inv, ip, integer, k2, asym):  # pragma: no cover - compiled; as amplifier_voltage
    v = gain * x
    a_sat = sat
    if asym != 0.0:
        a_sat = sat * (1.0 + asym) if v > 0 else sat * (1.0 - asym)
    a = np.abs(v / a_sat)
    if integer:  # |v/A|^(2p) by multiplication when 2p is whole (p = 2.5 by default): one pow per sample
        q = a
        for _ in range(ip - 1):
            q *= a
    else:
        q = a**p2
    if q == np.inf:  # a hard clip's limit (large p): v/(1 + q)^(1/2p) → ±A
        v = a_sat if v > 0 else -a_sat
    else:
        v = v / (1.0 + q) ** inv
    if k2 != 0.0:
        v = v + k2 * v * v / sat
    return 2.0 * v


@njit(cache=True, parallel=True)
def _rapp_parallel(x, gain, sat, p, k2, asym):  # pragma: no cover - compiled
    out = np.empty_like(x)
    p2 = 2.0 * p
    ip = int(p2)
    integer = ip == p2 and ip >= 1
    for i in prange(x.shape[0]):
        out[i] = _rapp_one(x[i], gain, sat, p2, 1.0 / p2, ip, integer, k2, asym)
    return out


@njit(cache=True)
def _rapp_serial(x, gain, sat, p, k2, asym):  # pragma: no cover - compiled
    out = np.empty_like(x)
    p2 = 2.0 * p
    ip = int(p2)
    integer = ip == p2 and ip >= 1
    for i in range(x.shape[0]):
        out[i] = _rapp_one(x[i], gain, sat, p2, 1.0 / p2, ip, integer, k2, asym)
    return out


@njit(cache=True)
def _rapp_scalar(x, gain, sat, p, k2, asym):  # pragma: no cover - compiled
    p2 = 2.0 * p
    ip = int(p2)
    return _rapp_one(x, gain, sat, p2, 1.0 / p2, ip, ip == p2 and ip >= 1, k2, asym)


def _rapp_kernel(x, gain, sat, p, k2, asym=0.0):
    """Rapp compression of ``x``: the parallel kernel for long arrays, the serial one (no thread launch) for
    short ones such as the one-sample calls of an FMU step. Both evaluate the same expression per sample."""
    return (_rapp_parallel if x.shape[0] >= PARALLEL_MIN else _rapp_serial)(x, gain, sat, p, k2, asym)
