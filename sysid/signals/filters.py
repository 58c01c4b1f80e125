"""Filtering and rate changes of array signals (time along axis 0): the moving average with a span, anti-aliased
integer decimation and rational resampling with a Kaiser-window FIR applied zero-phase and polyphase, and the
zero-phase Butterworth band-pass. Collected with the other steps in :mod:`sysid.signals.preprocess`."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from sysid.config import positive
from sysid.errors import ConfigError
from sysid.signals.checks import _as_float, _finite, _int_param

__all__ = [
    "moving_average",
    "decimate",
    "resample",
    "antialias_filter",
    "bandpass",
    "bandpass_design",
    "PASSBAND_DEFAULT",
    "ATTEN_DB_DEFAULT",
]


def _sps():
    """:mod:`scipy.signal`, imported on first use: its import takes about 1 s, which every command that only
    reads this module (``piezotwin preprocess --remove-offset``, ``--version``) would otherwise pay."""
    from scipy import signal

    return signal


PASSBAND_DEFAULT = 0.8  # fraction of the new Nyquist frequency kept within the pass-band tolerance
ATTEN_DB_DEFAULT = 65.0  # Kaiser design attenuation [dB]: >= 60 dB stop band, pass-band deviation <= 0.005 dB


# ---------------------------------------------------------------------------------------------- moving average
def moving_average(x: np.ndarray, span: int, mode: str = "centred") -> np.ndarray:
    """Moving average of ``span`` samples (dissertation §3.2: "a moving average filter, with a span of 100
    points"), same length as ``x``.

    ``mode="centred"`` (default): the window holds ``span//2`` samples before and ``(span-1)//2`` after the
    current one (odd span: symmetric, zero phase; even span such as 100: 50 before, 49 after, a lag of half a
    sample — the convention of MATLAB's ``movmean``). ``mode="causal"``: the current and the ``span-1``
    previous samples (a delay of ``(span-1)/2`` samples). Near the ends the window shrinks to the samples
    that exist (no padding). The dissertation does not say which form it used; its text does not mention a
    delay, so the centred form is the default.

    Frequency response (centred, interior): ``|H(f)| = |sin(pi f span/fs) / (span sin(pi f/fs))|`` — for
    span 100 at 100 MHz, nulls at multiples of 1 MHz and -13.5 dB at 1.35 MHz, the "loss of amplitude in the
    power spectrum" the dissertation reports for Figures 3.12 and 3.14.
    """
    x = _as_float(x)
    _finite(x, "moving_average")
    span = _int_param("moving average span", span, 1)
    if mode not in ("centred", "centered", "causal"):
        raise ConfigError(f"moving average mode must be centred or causal, got {mode!r}")
    n = x.shape[0]
    if span > n:
        raise ConfigError(f"moving average span {span} exceeds the signal length {n}")
    if span == 1:
        return x.copy()
    X = x.reshape(n, -1)
    mean = X.mean(axis=0)
    c = np.zeros((n + 1, X.shape[1]))
    np.cumsum(X - mean, axis=0, out=c[1:])  # centred values keep the running sum's round-off small
    if mode == "causal":
        before, after = span - 1, 0
    else:
        before, after = span // 2, (span - 1) // 2
    y = np.empty_like(X)
    # interior: full windows, lo = i - before, hi = i + after + 1 (slices, no index arrays)
    i0, i1 = before, n - after  # samples i with a full window
    if i1 > i0:
        y[i0:i1] = (c[i0 + after + 1 : i1 + after + 1] - c[i0 - before : i1 - before]) / span
    # ends: the window shrinks to the samples that exist
    for lo_i, hi_i in ((0, min(i0, n)), (max(i1, i0, 0), n)):
        if hi_i > lo_i:
            idx = np.arange(lo_i, hi_i)
            lo = np.maximum(idx - before, 0)
            hi = np.minimum(idx + after + 1, n)
            y[lo_i:hi_i] = (c[hi] - c[lo]) / (hi - lo)[:, None]
    y += mean
    return y.reshape(x.shape)


# ---------------------------------------------------------------------------------------------- decimation / resampling
def antialias_filter(
    up: int, down: int, passband: float = PASSBAND_DEFAULT, atten_db: float = ATTEN_DB_DEFAULT
) -> np.ndarray:
    """Linear-phase FIR low-pass for :func:`scipy.signal.resample_poly` with factors ``up/down``.

    Designed at the up-sampled rate (normalised to it): the pass band ends at ``passband`` x the lower of the
    two Nyquist frequencies, the stop band starts exactly at that Nyquist frequency (so nothing that would
    alias passes), and a Kaiser window (:func:`scipy.signal.kaiserord`) gives ``atten_db`` of stop-band
    attenuation and a pass-band deviation of at most ``10**(-atten_db/20)`` (0.005 dB for 65 dB).
    Unit DC gain (resample_poly multiplies by ``up``). Odd length, symmetric.
    """
    if not 0.0 < passband < 1.0:
        raise ConfigError(f"passband must lie in (0, 1) (fraction of the new Nyquist frequency), got {passband}")
    atten_db = positive("atten_db", atten_db)
    if atten_db < 21:
        raise ConfigError(f"atten_db must be >= 21 dB for a Kaiser design, got {atten_db}")
    m = max(up, down)
    # frequencies relative to the Nyquist frequency of the up-sampled rate
    f_stop = 1.0 / m
    f_pass = passband / m
    numtaps, beta = _sps().kaiserord(atten_db, f_stop - f_pass)
    numtaps |= 1  # odd: integer group delay, exactly compensated by resample_poly
    return _sps().firwin(numtaps, 0.5 * (f_pass + f_stop), window=("kaiser", beta), scale=True)


def decimate(
    x: np.ndarray,
    q: int,
    passband: float = PASSBAND_DEFAULT,
    atten_db: float = ATTEN_DB_DEFAULT,
    return_filter: bool = False,
):
    """Keep every ``q``-th sample after an anti-aliasing FIR low-pass (zero phase, polyphase).

    In-band (up to ``passband`` x the new Nyquist frequency ``fs/(2q)``) the amplitude changes by at most
    ``10**(-atten_db/20)`` (0.005 dB by default, well within 0.1 dB); every component above the new Nyquist
    frequency is attenuated by at least ``atten_db`` (65 dB by default, >= 60 dB). The first output sample is
    aligned with the first input sample; output length ``ceil(N/q)``.
    """
    x = _as_float(x)
    _finite(x, "decimate")
    q = _int_param("decimation factor q", q, 1)
    if q == 1:
        return (x.copy(), np.ones(1)) if return_filter else x.copy()
    if q > x.shape[0]:
        raise ConfigError(f"decimation factor {q} exceeds the signal length {x.shape[0]}")
    h = antialias_filter(1, q, passband, atten_db)
    y = _sps().resample_poly(x, 1, q, axis=0, window=h)
    return (y, h) if return_filter else y


def _ratio(fs: float, fs_new: float, max_den: int = 100000) -> tuple[int, int]:
    r = Fraction(fs_new) / Fraction(fs)
    approx = r.limit_denominator(max_den)
    if abs(float(approx) - float(r)) > 1e-12 * float(r) or approx.numerator > max_den:
        raise ConfigError(f"resample: fs_new/fs = {float(r):.12g} is not a ratio of integers up to {max_den}")
    return approx.numerator, approx.denominator


def resample(
    x: np.ndarray,
    fs: float,
    fs_new: float,
    passband: float = PASSBAND_DEFAULT,
    atten_db: float = ATTEN_DB_DEFAULT,
    return_filter: bool = False,
):
    """Rational resampling ``fs -> fs_new`` (e.g. 100 MHz -> 6.75 MHz = x 27/400, dissertation §3.2) with the
    anti-aliasing / anti-imaging FIR of :func:`antialias_filter` (same guarantees as :func:`decimate`,
    relative to the lower of the two Nyquist frequencies). Output length ``ceil(N * up / down)``."""
    x = _as_float(x)
    _finite(x, "resample")
    fs = positive("fs", fs)
    fs_new = positive("new sampling rate", fs_new)
    up, down = _ratio(fs, fs_new)
    if up == down:
        return (x.copy(), np.ones(1)) if return_filter else x.copy()
    if x.shape[0] * up < down:
        raise ConfigError(f"resample {fs:g} -> {fs_new:g} Hz leaves no sample of a {x.shape[0]}-sample signal")
    h = antialias_filter(up, down, passband, atten_db)
    y = _sps().resample_poly(x, up, down, axis=0, window=h)
    return (y, h) if return_filter else y


# ---------------------------------------------------------------------------------------------- band-pass
def bandpass_design(fs: float, fmin: float, fmax: float, order: int = 5) -> np.ndarray:
    """Second-order sections of the digital Butterworth band-pass (order ``order`` prototype, i.e. ``2*order``
    poles) with -3 dB edges ``fmin``, ``fmax`` [Hz] (bilinear transform with pre-warping)."""
    fs = positive("fs", fs)
    order = _int_param("band-pass order", order, 1)
    try:
        fmin, fmax = float(fmin), float(fmax)
    except (TypeError, ValueError):
        raise ConfigError(f"band-pass edges must be numbers, got {fmin!r}, {fmax!r}") from None
    if not (math.isfinite(fmin) and math.isfinite(fmax)) or fmin <= 0:
        raise ConfigError(f"band-pass fmin must be > 0 Hz, got {fmin:g}")
    if fmin >= fmax:
        raise ConfigError(f"band-pass fmin ({fmin:g} Hz) must be below fmax ({fmax:g} Hz)")
    if fmax >= fs / 2:
        raise ConfigError(f"band-pass fmax ({fmax:g} Hz) must be below the Nyquist frequency fs/2 = {fs / 2:g} Hz")
    return _sps().butter(order, [fmin, fmax], btype="bandpass", fs=fs, output="sos")


def bandpass(x: np.ndarray, fs: float, fmin: float, fmax: float, order: int = 5) -> np.ndarray:
    """Zero-phase Butterworth band-pass (dissertation §3.2: "a fifth-order band-pass filter"), applied
    forward and backward (:func:`scipy.signal.sosfiltfilt`): no phase shift, magnitude ``|H(f)|^2`` of the
    order-``order`` design, i.e. -6 dB at ``fmin`` and ``fmax`` and ``20*order`` dB/decade x 2 outside."""
    x = _as_float(x)
    _finite(x, "bandpass")
    sos = bandpass_design(fs, fmin, fmax, order)
    padlen = min(3 * (2 * sos.shape[0] + 1), x.shape[0] - 1)
    return _sps().sosfiltfilt(sos, x, axis=0, padlen=padlen)
