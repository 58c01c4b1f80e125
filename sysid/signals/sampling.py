"""Segments of a record and the choice of its sampling rate: fixed-length (overlapping) segment bounds, and the
covariance-based rate suggestion (autocovariance of the output and of its square, their first minima).
Collected with the other steps in :mod:`sysid.signals.preprocess`."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sysid.config import positive
from sysid.errors import ConfigError, DataError
from sysid.signals.checks import _as_float, _finite, _int_param

__all__ = ["segment", "segment_bounds", "autocovariance", "suggest_rate"]


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
    import scipy.fft  # here, not at the top: every CLI start would pay its import (~0.2 s)

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
        raise DataError(
            f"suggest_rate: the {which} autocovariance has no minimum within {max_lag} lags;"
            " record longer data or raise max_lag"
        )
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
