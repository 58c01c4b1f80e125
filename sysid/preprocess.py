"""Signal preprocessing (dissertation §2.3 and §3.2), in the manner of :mod:`scipy.signal`.

Array functions (time along axis 0; 1-D or 2-D ``(N, channels)``; ``fs`` explicit where it matters):

- :func:`remove_offset`, :func:`detrend` — offset and polynomial trend removal;
- :func:`hampel` — outlier detection and replacement by the local median, with a report of every change;
- :func:`fill_missing` — interpolation of missing (NaN) samples, with the filled indices;
- :func:`moving_average` — the dissertation's moving-average filter with a span (§3.2: 100 points);
- :func:`decimate`, :func:`resample` — anti-aliased integer decimation and rational resampling
  (§3.2: 100 MHz -> 6.75 MHz) with a Kaiser-window FIR designed for a stated pass-band flatness and
  stop-band attenuation, applied as a zero-phase polyphase filter (:func:`scipy.signal.resample_poly`);
- :func:`bandpass` — zero-phase Butterworth band-pass (§3.2: fifth order), :func:`scipy.signal.sosfiltfilt`;
- :func:`segment` / :func:`segment_bounds` — fixed-length (overlapping) segments;
- :func:`suggest_rate` — the covariance-based choice of the sampling rate (§3.2, ref. [83], Aguirre).

Record level: :func:`apply_steps` applies a list of steps in order to ``u`` and ``y`` and appends one entry
``{"step", "params", "changes"}`` per step to ``record.meta["preprocessing"]`` (the same list in which
:func:`sysid.io.read_record` records ``fill_missing`` when it interpolates at read time).
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Any, Iterable

import numpy as np
import scipy.fft
from numba import njit
from scipy import signal as sps

from sysid.config import positive
from sysid.errors import ConfigError, DataError
from sysid.record import Record

__all__ = [
    "remove_offset",
    "detrend",
    "hampel",
    "fill_missing",
    "moving_average",
    "decimate",
    "resample",
    "antialias_filter",
    "bandpass",
    "bandpass_design",
    "segment",
    "segment_bounds",
    "autocovariance",
    "suggest_rate",
    "apply_steps",
    "STEPS",
]

PASSBAND_DEFAULT = 0.8  # fraction of the new Nyquist frequency kept within the pass-band tolerance
ATTEN_DB_DEFAULT = 65.0  # Kaiser design attenuation [dB]: >= 60 dB stop band, pass-band deviation <= 0.005 dB


def _as_float(x: Any, name: str = "x") -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim not in (1, 2) or arr.shape[0] == 0:
        raise DataError(f"{name}: expected a non-empty 1-D or 2-D (samples x channels) array, got shape {arr.shape}")
    return arr


def _finite(x: np.ndarray, name: str) -> None:
    if not np.isfinite(x).all():
        raise DataError(f"{name}: has non-finite samples; fill missing samples first (fill_missing)")


def _int_param(name: str, value: Any, lo: int) -> int:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{name} must be an integer, got {value!r}") from None
    if not math.isfinite(v) or v != int(v) or v < lo:
        raise ConfigError(f"{name} must be an integer >= {lo}, got {value!r}")
    return int(v)




# ---------------------------------------------------------------------------------------------- offset / trend
def remove_offset(x: np.ndarray) -> np.ndarray:
    """``x`` minus its mean (per channel)."""
    x = _as_float(x)
    _finite(x, "remove_offset")
    return x - x.mean(axis=0)


def detrend(x: np.ndarray, order: int = 1, return_coefficients: bool = False):
    """Remove a least-squares polynomial trend of ``order`` (0 = offset, 1 = linear drift, ...) per channel.

    The polynomial is fitted in the normalised time ``tau = 2 n/(N-1) - 1`` (well conditioned for long
    records). ``return_coefficients=True`` also returns the coefficients (lowest power first, per channel),
    in signal units per power of ``tau``.
    """
    x = _as_float(x)
    _finite(x, "detrend")
    order = _int_param("detrend order", order, 0)
    n = x.shape[0]
    if order >= n:
        raise ConfigError(f"detrend order {order} needs more than {order} samples, got {n}")
    tau = np.linspace(-1.0, 1.0, n) if n > 1 else np.zeros(1)
    V = np.polynomial.legendre.legvander(tau, order)  # orthogonal basis on [-1, 1]
    X = x.reshape(n, -1)
    coef, *_ = np.linalg.lstsq(V, X, rcond=None)
    y = (X - V @ coef).reshape(x.shape)
    if return_coefficients:
        # express in the monomial basis of tau for the report
        mono = np.stack([np.polynomial.legendre.leg2poly(coef[:, c]) for c in range(coef.shape[1])], axis=1)
        return y, mono
    return y


# ---------------------------------------------------------------------------------------------- outliers / missing
@njit(cache=True)
def _hampel_core(xp: np.ndarray, n: int, k: int, med: np.ndarray, mad: np.ndarray) -> None:  # pragma: no cover - numba
    """Running median and MAD of the windows ``xp[i : i + 2k + 1]``, ``i = 0..n-1``, in O(window) per sample.

    A sorted copy of the window is updated by one deletion and one insertion per step; the MAD (the median
    of |x_j - m|) is the k-th smallest deviation, found by walking outward from the median of the sorted
    window (the deviations on each side are already sorted).
    """
    w = 2 * k + 1
    s = np.sort(xp[:w].copy())
    for i in range(n):
        if i > 0:
            old = xp[i - 1]
            new = xp[i + w - 1]
            # delete old (binary search for its position)
            lo, hi = 0, w
            while lo < hi:
                mid = (lo + hi) // 2
                if s[mid] < old:
                    lo = mid + 1
                else:
                    hi = mid
            for j in range(lo, w - 1):
                s[j] = s[j + 1]
            # insert new into s[0 : w-1]
            lo, hi = 0, w - 1
            while lo < hi:
                mid = (lo + hi) // 2
                if s[mid] < new:
                    lo = mid + 1
                else:
                    hi = mid
            for j in range(w - 1, lo, -1):
                s[j] = s[j - 1]
            s[lo] = new
        m = s[k]
        med[i] = m
        # k-th smallest of |s_j - m| (0-based; index k itself has deviation 0)
        left, right = k - 1, k + 1
        d = 0.0
        for _ in range(k):
            if left < 0:
                d = s[right] - m
                right += 1
            elif right >= w:
                d = m - s[left]
                left -= 1
            elif m - s[left] <= s[right] - m:
                d = m - s[left]
                left -= 1
            else:
                d = s[right] - m
                right += 1
        mad[i] = d


def _hampel_1d(x: np.ndarray, k: int, n_sigma: float):
    n = x.size
    pad = np.pad(x, k, mode="reflect") if n > k else np.pad(x, k, mode="edge")
    med = np.empty(n)
    mad = np.empty(n)
    _hampel_core(np.ascontiguousarray(pad), n, k, med, mad)
    sigma = 1.482602218505602 * mad  # MAD -> standard deviation of a Gaussian: 1/Phi^-1(3/4)
    out = np.abs(x - med) > n_sigma * sigma
    return out, med, sigma


def hampel(x: np.ndarray, window: int = 10, n_sigma: float = 3.0):
    """Hampel identifier: a sample is an outlier when it lies more than ``n_sigma`` robust standard deviations
    (1.4826 x the median absolute deviation) from the median of the ``2*window + 1`` samples centred on it;
    it is replaced by that median. Edges use a reflected window.

    Default half-width 10 (21-sample window): on white Gaussian noise it flags 1.4 % of the samples (window 3,
    MATLAB's default, flags 4.8 %; the asymptotic rate for n_sigma=3 is 0.27 %), measured on 2e5 samples.

    Returns ``(y, changes)``: the cleaned copy and a list with one dict per replaced sample,
    ``{"index", "channel", "value", "replacement"}`` (nothing is changed without being reported).
    A window in which more than half the samples are equal has MAD 0, and any other value in it is flagged.
    """
    x = _as_float(x)
    _finite(x, "hampel")
    window = _int_param("hampel window (half-width)", window, 1)
    n_sigma = positive("hampel n_sigma", n_sigma)
    if window >= x.shape[0]:  # the window would be mostly edge padding: its MAD says nothing about the data
        raise ConfigError(f"hampel window half-width {window} must be smaller than the signal length {x.shape[0]}")
    X = x.reshape(x.shape[0], -1)
    Y = X.copy()
    changes: list[dict[str, Any]] = []
    for c in range(X.shape[1]):
        out, med, _ = _hampel_1d(X[:, c], window, n_sigma)
        idx = np.flatnonzero(out)
        Y[idx, c] = med[idx]
        changes.extend({"index": int(i), "channel": c, "value": float(X[i, c]), "replacement": float(med[i])} for i in idx)
    changes.sort(key=lambda d: (d["index"], d["channel"]))
    return Y.reshape(x.shape), changes


def fill_missing(x: np.ndarray, method: str = "linear"):
    """Interpolate missing samples (NaN) per channel: ``method`` ``linear``, ``pchip`` (shape-preserving
    cubic) or ``nearest``; samples before the first / after the last valid one take its value.

    Returns ``(y, filled)`` with the sorted list of filled sample indices. Infinite samples are not
    "missing" and raise :class:`DataError`.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.ndim not in (1, 2) or x.shape[0] == 0:
        raise DataError(f"fill_missing: expected a non-empty 1-D or 2-D array, got shape {x.shape}")
    if method not in ("linear", "pchip", "nearest"):
        raise ConfigError(f"fill_missing method must be linear, pchip or nearest, got {method!r}")
    if np.isinf(x).any():
        raise DataError("fill_missing: signal has infinite samples; only missing (NaN) samples can be interpolated")
    bad = np.isnan(x)
    if not bad.any():
        return x.copy(), []
    X = x.reshape(x.shape[0], -1).copy()
    n = np.arange(X.shape[0], dtype=np.float64)
    for c in range(X.shape[1]):
        b = np.isnan(X[:, c])
        if not b.any():
            continue
        good = ~b
        if not good.any():
            raise DataError(f"fill_missing: channel {c} has no valid sample to interpolate from")
        ng, xg = n[good], X[good, c]
        if method == "linear" or good.sum() < 2:
            X[b, c] = np.interp(n[b], ng, xg)
        elif method == "nearest":
            pos = np.clip(np.searchsorted(ng, n[b]), 1, ng.size - 1)
            left, right = ng[pos - 1], ng[pos]
            take = np.where(n[b] - left <= right - n[b], pos - 1, pos)
            X[b, c] = xg[take]
        else:
            from scipy.interpolate import PchipInterpolator

            X[b, c] = PchipInterpolator(ng, xg, extrapolate=False)(np.clip(n[b], ng[0], ng[-1]))
    rows = np.flatnonzero(bad.reshape(x.shape[0], -1).any(axis=1)).tolist()
    return X.reshape(x.shape), rows


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
def antialias_filter(up: int, down: int, passband: float = PASSBAND_DEFAULT, atten_db: float = ATTEN_DB_DEFAULT) -> np.ndarray:
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
    numtaps, beta = sps.kaiserord(atten_db, f_stop - f_pass)
    numtaps |= 1  # odd: integer group delay, exactly compensated by resample_poly
    return sps.firwin(numtaps, 0.5 * (f_pass + f_stop), window=("kaiser", beta), scale=True)


def decimate(x: np.ndarray, q: int, passband: float = PASSBAND_DEFAULT, atten_db: float = ATTEN_DB_DEFAULT,
             return_filter: bool = False):
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
    y = sps.resample_poly(x, 1, q, axis=0, window=h)
    return (y, h) if return_filter else y


def _ratio(fs: float, fs_new: float, max_den: int = 100000) -> tuple[int, int]:
    r = Fraction(fs_new) / Fraction(fs)
    approx = r.limit_denominator(max_den)
    if abs(float(approx) - float(r)) > 1e-12 * float(r) or approx.numerator > max_den:
        raise ConfigError(f"resample: fs_new/fs = {float(r):.12g} is not a ratio of integers up to {max_den}")
    return approx.numerator, approx.denominator


def resample(x: np.ndarray, fs: float, fs_new: float, passband: float = PASSBAND_DEFAULT,
             atten_db: float = ATTEN_DB_DEFAULT, return_filter: bool = False):
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
    y = sps.resample_poly(x, up, down, axis=0, window=h)
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
    return sps.butter(order, [fmin, fmax], btype="bandpass", fs=fs, output="sos")


def bandpass(x: np.ndarray, fs: float, fmin: float, fmax: float, order: int = 5) -> np.ndarray:
    """Zero-phase Butterworth band-pass (dissertation §3.2: "a fifth-order band-pass filter"), applied
    forward and backward (:func:`scipy.signal.sosfiltfilt`): no phase shift, magnitude ``|H(f)|^2`` of the
    order-``order`` design, i.e. -6 dB at ``fmin`` and ``fmax`` and ``20*order`` dB/decade x 2 outside."""
    x = _as_float(x)
    _finite(x, "bandpass")
    sos = bandpass_design(fs, fmin, fmax, order)
    padlen = min(3 * (2 * sos.shape[0] + 1), x.shape[0] - 1)
    return sps.sosfiltfilt(sos, x, axis=0, padlen=padlen)


# ---------------------------------------------------------------------------------------------- segmentation
def segment_bounds(n: int, length: int, overlap: int = 0) -> list[tuple[int, int]]:
    """``(start, stop)`` of consecutive segments of ``length`` samples, each overlapping the previous one by
    ``overlap`` samples; an incomplete tail is left out (its size is ``n - bounds[-1][1]``)."""
    length = _int_param("segment length", length, 1)
    overlap = _int_param("segment overlap", overlap, 0)
    if overlap >= length:
        raise ConfigError(f"segment overlap ({overlap}) must be smaller than the length ({length})")
    if length > n:
        raise ConfigError(f"segment length {length} exceeds the signal length {n}")
    step = length - overlap
    return [(s, s + length) for s in range(0, n - length + 1, step)]


def segment(x: np.ndarray, length: int, overlap: int = 0) -> np.ndarray:
    """Segments of ``length`` samples (overlap ``overlap``) as an array ``(n_segments, length[, channels])``
    (a read-only view, no copy). The incomplete tail is left out — see :func:`segment_bounds`."""
    x = _as_float(x)
    b = segment_bounds(x.shape[0], length, overlap)
    step = b[1][0] - b[0][0] if len(b) > 1 else length
    v = np.lib.stride_tricks.sliding_window_view(x, length, axis=0)[::step][: len(b)]
    return np.moveaxis(v, -1, 1) if x.ndim == 2 else v


# ---------------------------------------------------------------------------------------------- sampling rate (Aguirre)
def autocovariance(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased sample autocovariance ``r[k] = (1/N) sum (x[n]-m)(x[n+k]-m)``, ``k = 0..max_lag`` (FFT)."""
    x = np.asarray(x, dtype=np.float64).ravel()
    n = x.size
    max_lag = min(int(max_lag), n - 1)
    x = x - x.mean()
    nfft = scipy.fft.next_fast_len(n + max_lag + 1, real=True)
    X = scipy.fft.rfft(x, nfft, workers=-1)
    r = scipy.fft.irfft(X.real**2 + X.imag**2, nfft, workers=-1)[: max_lag + 1]
    return r / n


def _first_minimum(r: np.ndarray) -> int | None:
    d = np.diff(r)
    # first k >= 1 with r[k] <= r[k-1] and r[k] < r[k+1]
    k = np.flatnonzero((d[:-1] <= 0) & (d[1:] > 0))
    return int(k[0] + 1) if k.size else None


def suggest_rate(y: np.ndarray, fs: float | None = None, max_lag: int | None = None) -> dict[str, Any]:
    r"""Covariance-based choice of the sampling rate (dissertation §3.2, ref. [83]: Aguirre; the rule of
    Billings & Aguirre, "Effects of the sampling time on the dynamics and identification of nonlinear
    models", Int. J. Bifurcation and Chaos 5(6), 1995, as restated in Aguirre's textbook).

    From purposely oversampled data ``y``:

    1. :math:`\tau_y` — lag of the first minimum of the linear autocovariance :math:`r_{y'y'}(\tau)`, with
       :math:`y' = y - \bar y`;
    2. :math:`\tau_{y^2}` — lag of the first minimum of the nonlinear autocovariance
       :math:`r_{y'^2 y'^2}(\tau)` of the squared signal, its mean removed;
    3. :math:`\tau_m = \min(\tau_y, \tau_{y^2})`, and the sampling time should satisfy
       :math:`\tau_m/20 \le T_s \le \tau_m/10`, i.e. the decimated signal has its first minimum at 10 to 20
       lags.

    Returns ``factor`` — the largest decimation factor that respects the rule, ``floor(tau_m/10)`` (at least
    1; 1 means the data are not oversampled by this criterion) —, ``factor_range`` (the integer range
    ``[ceil(tau_m/20), floor(tau_m/10)]``, may be empty), the lags ``tau_linear``, ``tau_nonlinear``,
    ``tau_min`` (samples), and with ``fs`` the corresponding ``fs_suggested`` [Hz] and lags in seconds.
    ``max_lag`` (default ``N//2``) bounds the search; no minimum before it raises :class:`DataError`.
    """
    y = _as_float(y, "suggest_rate")
    _finite(y, "suggest_rate")
    if y.ndim == 2:
        if y.shape[1] != 1:
            raise DataError("suggest_rate: give one output channel")
        y = y[:, 0]
    n = y.size
    if n < 8:
        raise DataError(f"suggest_rate: {n} samples are too few")
    max_lag = n // 2 if max_lag is None else _int_param("max_lag", max_lag, 2)
    yc = y - y.mean()
    r_lin = autocovariance(yc, max_lag)
    z = yc * yc
    r_nl = autocovariance(z - z.mean(), max_lag)
    tau_l = _first_minimum(r_lin)
    tau_n = _first_minimum(r_nl)
    if tau_l is None or tau_n is None:
        which = "linear" if tau_l is None else "nonlinear (y^2)"
        raise DataError(f"suggest_rate: the {which} autocovariance has no minimum within {max_lag} lags;"
                        " record longer data or raise max_lag")
    tau_m = min(tau_l, tau_n)
    out: dict[str, Any] = {
        "tau_linear": tau_l,
        "tau_nonlinear": tau_n,
        "tau_min": tau_m,
        "factor": max(1, tau_m // 10),
        "factor_range": [int(math.ceil(tau_m / 20)), int(tau_m // 10)],
        "rule": "tau_m/20 <= Ts <= tau_m/10, tau_m = min(first minimum of r_yy, of r_y2y2) (Billings & Aguirre 1995)",
    }
    if fs is not None:
        fs = positive("fs", fs)
        out["fs"] = fs
        out["fs_suggested"] = fs / out["factor"]
        out["tau_linear_s"] = tau_l / fs
        out["tau_nonlinear_s"] = tau_n / fs
    return out


# ---------------------------------------------------------------------------------------------- record level
STEPS = ("remove_offset", "detrend", "hampel", "fill_missing", "moving_average", "decimate", "resample", "bandpass",
         "segment", "suggest_rate")
_ALIASES = {"outliers": "hampel", "offset": "remove_offset", "fill-missing": "fill_missing",
            "moving-average": "moving_average", "suggest-rate": "suggest_rate"}
_PARAMS = {
    "remove_offset": set(),
    "detrend": {"order"},
    "hampel": {"window", "n_sigma"},
    "fill_missing": {"method"},
    "moving_average": {"span", "mode"},
    "decimate": {"q", "passband", "atten_db"},
    "resample": {"fs_new", "passband", "atten_db"},
    "bandpass": {"fmin", "fmax", "order"},
    "segment": {"length", "overlap"},
    "suggest_rate": {"max_lag"},
}
_PER_SIGNAL = {"remove_offset", "detrend", "hampel", "moving_average", "bandpass"}  # may be limited to u or y


def _normalise_step(step: Any) -> tuple[str, dict[str, Any]]:
    if isinstance(step, str):
        name, params = step, {}
    elif isinstance(step, dict):
        params = dict(step)
        name = params.pop("step", None)
        if name is None:
            raise ConfigError(f"preprocessing step {step!r} has no 'step' name")
    else:
        try:
            name, params = step
            params = dict(params or {})
        except (TypeError, ValueError):
            raise ConfigError(f"preprocessing step must be a name, (name, params) or a dict, got {step!r}") from None
    name = _ALIASES.get(str(name), str(name))
    if name not in _PARAMS:
        raise ConfigError(f"unknown preprocessing step {name!r}; valid: {', '.join(STEPS)}")
    allowed = _PARAMS[name] | ({"signals"} if name in _PER_SIGNAL else set())
    unknown = set(params) - allowed
    if unknown:
        raise ConfigError(f"preprocessing step {name}: unknown parameter(s) {', '.join(sorted(unknown))};"
                          f" valid: {', '.join(sorted(allowed)) or 'none'}")
    return name, params


def apply_steps(record: Record, steps: Iterable[Any]) -> Record:
    """Apply preprocessing ``steps`` to ``record`` in the order given and return a new Record.

    A step is a name (``"detrend"``), a pair ``(name, params)`` or a dict ``{"step": name, **params}``;
    names are those of :data:`STEPS` (``outliers`` is an alias of ``hampel``). Steps act on ``u`` and ``y``;
    ``remove_offset``, ``detrend``, ``hampel``, ``moving_average`` and ``bandpass`` accept
    ``signals="u"|"y"|"both"``. ``decimate`` and ``resample`` always act on both and change ``fs``;
    ``segment`` writes ``meta["segments"]`` (``Record.segments()`` splits by it); ``suggest_rate`` changes
    nothing and reports the Aguirre suggestion computed on ``y`` (its first channel; on ``u`` for an
    input-only record). A Record cannot hold missing samples (they are refused, or filled by
    ``read_record(..., fill_missing=True)`` when the file is read), so ``fill_missing`` here only records that
    nothing was missing.

    Each step appends ``{"step": name, "params": {...}, "changes": {...}}`` to ``meta["preprocessing"]``:
    the offsets / trend coefficients removed, every outlier replaced (index, channel, value, replacement),
    the filled indices, the rates and lengths before and after, the filter length, the segments.
    """
    rec = record.replace()
    log = rec.meta.setdefault("preprocessing", [])
    for raw in steps:
        name, params = _normalise_step(raw)
        signals = params.pop("signals", "both") if name in _PER_SIGNAL else "both"
        if signals not in ("u", "y", "both"):
            raise ConfigError(f"preprocessing step {name}: signals must be u, y or both, got {signals!r}")
        targets = ["u", "y"] if signals == "both" else [signals]
        targets = [t for t in targets if getattr(rec, t) is not None]
        if signals == "y" and rec.y is None:
            raise DataError(f"{rec.source}: step {name} asks for y but the record has no output")
        changes: dict[str, Any] = {}
        new: dict[str, Any] = {}
        fs = rec.fs
        if name in ("decimate", "resample") and rec.meta.get("segments"):
            raise ConfigError(f"step {name} after segment would invalidate the segment indices; segment last")
        if name == "remove_offset":
            for t in targets:
                x = getattr(rec, t)
                changes.setdefault("offset", {})[t] = x.mean(axis=0).tolist()
                new[t] = remove_offset(x)
        elif name == "detrend":
            order = params.get("order", 1)
            for t in targets:
                new[t], coef = detrend(getattr(rec, t), order=order, return_coefficients=True)
                changes.setdefault("trend_coefficients", {})[t] = coef.T.tolist()
        elif name == "hampel":
            for t in targets:
                new[t], ch = hampel(getattr(rec, t), window=params.get("window", 10), n_sigma=params.get("n_sigma", 3.0))
                changes.setdefault("replaced", {})[t] = ch
            changes["n_replaced"] = {t: len(changes["replaced"][t]) for t in targets}
        elif name == "fill_missing":
            for t in targets:
                new[t], filled = fill_missing(getattr(rec, t), method=params.get("method", "linear"))
                changes.setdefault("filled_indices", {})[t] = filled
        elif name == "moving_average":
            if "span" not in params:
                raise ConfigError("preprocessing step moving_average needs span")
            for t in targets:
                new[t] = moving_average(getattr(rec, t), params["span"], params.get("mode", "centred"))
        elif name in ("decimate", "resample"):
            if name == "decimate":
                if "q" not in params:
                    raise ConfigError("preprocessing step decimate needs q")
                q = _int_param("decimation factor q", params["q"], 1)
                fs_new = fs / q
                fn = lambda x: decimate(x, q, params.get("passband", PASSBAND_DEFAULT),  # noqa: E731
                                        params.get("atten_db", ATTEN_DB_DEFAULT), return_filter=True)
            else:
                if "fs_new" not in params:
                    raise ConfigError("preprocessing step resample needs fs_new")
                fs_new = positive("new sampling rate", params["fs_new"])
                fn = lambda x: resample(x, fs, fs_new, params.get("passband", PASSBAND_DEFAULT),  # noqa: E731
                                        params.get("atten_db", ATTEN_DB_DEFAULT), return_filter=True)
            for t in targets:
                new[t], h = fn(getattr(rec, t))
            changes.update({"fs_before": fs, "fs_after": fs_new, "n_before": len(rec), "n_after": int(new["u"].shape[0]),
                            "filter_taps": int(h.size)})
            new["fs"] = fs_new
        elif name == "bandpass":
            if "fmin" not in params or "fmax" not in params:
                raise ConfigError("preprocessing step bandpass needs fmin and fmax")
            for t in targets:
                new[t] = bandpass(getattr(rec, t), fs, params["fmin"], params["fmax"], params.get("order", 5))
        elif name == "segment":
            if "length" not in params:
                raise ConfigError("preprocessing step segment needs length")
            b = segment_bounds(len(rec), params["length"], params.get("overlap", 0))
            rec.meta["segments"] = [{"start": s, "stop": e} for s, e in b]
            changes = {"n_segments": len(b), "dropped_tail": len(rec) - b[-1][1]}
        elif name == "suggest_rate":
            target = rec.y if rec.y is not None else rec.u
            if target.ndim == 2:
                target = target[:, 0]
            changes = {"signal": "y" if rec.y is not None else "u", "channel": 0,
                       **suggest_rate(target, fs=fs, max_lag=params.get("max_lag"))}
        if new:
            kw = {k: v for k, v in new.items() if k in ("u", "y", "fs")}
            meta = rec.meta
            rec = rec.replace(**kw)
            rec.meta = meta
        log.append({"step": name, "params": {**params, **({"signals": signals} if name in _PER_SIGNAL else {})},
                    "changes": changes})
        rec.meta["preprocessing"] = log
    return rec
