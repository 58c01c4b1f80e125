"""Nonparametric frequency response functions (FRF), in the manner of :mod:`scipy.signal`.

- :func:`frf_welch` — H1 estimate :math:`\\hat G(f) = \\hat S_{uy}(f) / \\hat S_{uu}(f)` from arbitrary records
  (Welch-averaged cross and auto spectra, window and overlap of the caller's choice) with the magnitude-squared
  coherence :math:`\\gamma^2 = |S_{uy}|^2 / (S_{uu} S_{yy})` and its standard deviation
  :math:`\\sigma_{|G|} \\approx |G|\\sqrt{(1-\\gamma^2)/(2 n_d \\gamma^2)}` (Bendat & Piersol, *Random Data*,
  4th ed., eq. 9.90, :math:`n_d` independent segments).
- :func:`frf_periodic` — periodic (multisine) records of ``P`` periods: the DFT of every period, averaged per
  line over the periods, :math:`\\hat G(k) = \\hat Y(k)/\\hat U(k)` at the excited lines, and the variance of
  :math:`\\hat G` from the period-to-period spread (Pintelon & Schoukens, *System Identification: A Frequency
  Domain Approach*, 2nd ed. 2012, §2.4 and eqs. 2-36 to 2-40).
- :func:`period_spectra` / :func:`excited_lines` — the building blocks the BLA (:mod:`sysid.linear.bla`) reuses.

Frequencies are in Hz, ``fs`` is explicit, arrays in, a small :class:`FRF` record out.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.signal

from sysid.errors import ConfigError, DataError

__all__ = ["FRF", "frf_welch", "frf_periodic", "period_spectra", "excited_lines", "EXCITATION_DB"]

#: a line is "excited" when its input amplitude is within this many dB of the strongest line
EXCITATION_DB = 40.0


@dataclass
class FRF:
    """A nonparametric FRF: complex ``G`` at ``f_hz`` [Hz] with its uncertainty.

    ``coherence`` (H1 estimates) or ``std`` (standard deviation of the complex ``G`` per line, periodic
    estimates) may be ``None``. ``lines`` are the DFT line indices of a periodic estimate (frequency
    ``lines * fs / period_samples``); ``info`` holds how it was made (method, periods, segments ...).
    """

    f_hz: np.ndarray
    G: np.ndarray
    coherence: np.ndarray | None = None
    std: np.ndarray | None = None
    lines: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def magnitude_db(self) -> np.ndarray:
        """20 log10 |G| [dB]."""
        with np.errstate(divide="ignore"):
            return 20.0 * np.log10(np.abs(self.G))

    @property
    def phase_deg(self) -> np.ndarray:
        """Unwrapped phase of G [degrees]."""
        return np.degrees(np.unwrap(np.angle(self.G)))


def _siso(u: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if u.ndim != 1 or y.ndim != 1:
        raise DataError(f"FRF: single-input single-output signals expected (1-D), got u{u.shape}, y{y.shape}")
    if u.size != y.size:
        raise DataError(f"FRF: u and y have unequal lengths ({u.size} and {y.size})")
    if not (np.isfinite(u).all() and np.isfinite(y).all()):
        raise DataError("FRF: u or y has non-finite samples")
    return u, y


def frf_welch(
    u: Any,
    y: Any,
    fs: float,
    window: str | tuple = "hann",
    nperseg: int | None = None,
    noverlap: int | None = None,
    detrend: str | bool = "constant",
) -> FRF:
    """H1 FRF estimate with coherence from arbitrary (non-periodic) records (Welch's method).

    Parameters
    ----------
    u, y : array_like
        Input and output samples, 1-D and of equal length.
    fs : float
        Sampling rate [Hz].
    window : str or tuple
        Window of :func:`scipy.signal.get_window` (default Hann).
    nperseg : int, optional
        Segment length; default ``min(N, 1024)`` — a longer segment gives a finer resolution ``fs/nperseg``
        and fewer averages (more variance).
    noverlap : int, optional
        Overlap in samples (default ``nperseg // 2``).
    detrend : str or False
        Per-segment detrending as in :func:`scipy.signal.welch`.

    Returns
    -------
    FRF
        ``f_hz``, ``G`` = :math:`S_{uy}/S_{uu}` (H1, unbiased for output noise), ``coherence`` and ``std``
        (Bendat & Piersol eq. 9.90, std of |G|, with :math:`n_d` the number of segments; overlapping segments
        are not independent, so with overlap this std is somewhat optimistic).
    """
    u, y = _siso(u, y)
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0:
        raise ConfigError(f"FRF: fs must be positive, got {fs}")
    n = u.size
    if nperseg is None:
        nperseg = min(n, 1024)
    nperseg = int(nperseg)
    if nperseg < 8 or nperseg > n:
        raise ConfigError(f"FRF: nperseg must lie in 8..{n} (record length), got {nperseg}")
    if noverlap is None:
        noverlap = nperseg // 2
    noverlap = int(noverlap)
    if not 0 <= noverlap < nperseg:
        raise ConfigError(f"FRF: noverlap must lie in 0..{nperseg - 1}, got {noverlap}")
    kw = dict(fs=fs, window=window, nperseg=nperseg, noverlap=noverlap, detrend=detrend)
    try:
        f, s_uu = scipy.signal.welch(u, **kw)
        _, s_yy = scipy.signal.welch(y, **kw)
        _, s_uy = scipy.signal.csd(u, y, **kw)  # scipy: conj(U) * Y, so S_uy / S_uu is H1
    except ValueError as exc:
        raise ConfigError(f"FRF: {exc}") from None
    with np.errstate(divide="ignore", invalid="ignore"):
        G = s_uy / s_uu
        coh = np.clip(np.abs(s_uy) ** 2 / (s_uu * s_yy), 0.0, 1.0)
        n_seg = 1 + (n - nperseg) // (nperseg - noverlap)
        std = np.abs(G) * np.sqrt((1.0 - coh) / (2.0 * n_seg * coh))
    return FRF(
        f_hz=f,
        G=G,
        coherence=coh,
        std=std,
        info={
            "method": "H1 (Welch)",
            "window": window,
            "nperseg": nperseg,
            "noverlap": noverlap,
            "segments": int(n_seg),
            "fs": fs,
        },
    )


def period_spectra(x: Any, periods: int, drop: int = 0, detrend: int = 0) -> np.ndarray:
    """DFT of every period: array ``(P - drop, n0 // 2 + 1)`` of ``rfft`` of each period, scaled by ``1/n0``.

    ``x`` must hold exactly ``periods`` periods (its length divisible by ``periods``); the first ``drop``
    periods (transient) are left out.

    ``detrend = d > 0`` removes a slow trend (drift, the tail of a transient) of polynomial degree
    ``min(d, P' - 1)`` (``P'`` periods used) fitted to the *means of the periods* at the period centres: a
    periodic steady state has the same mean in every period, so only what differs between periods is removed
    and the periodic part is left untouched. Without it a drift — identical in every period after the
    period average, as a ramp is — would show at every line, detection lines included.
    """
    x = np.asarray(x, dtype=float)
    periods = int(periods)
    if periods < 1:
        raise ConfigError(f"periods must be >= 1, got {periods}")
    if x.ndim != 1:
        raise DataError(f"periodic FRF: 1-D signals expected, got shape {x.shape}")
    if x.size % periods:
        raise DataError(
            f"periodic FRF: {x.size} samples do not split into {periods} equal periods "
            f"({x.size / periods:.6g} samples each); give the number of periods the record holds"
        )
    drop = int(drop)
    if not 0 <= drop < periods:
        raise ConfigError(f"drop (transient periods) must lie in 0..{periods - 1}, got {drop}")
    n0 = x.size // periods
    frames = x.reshape(periods, n0)[drop:]
    deg = min(int(detrend), frames.shape[0] - 1)
    if deg > 0:
        t = np.arange(frames.size, dtype=float).reshape(frames.shape) / n0  # time in periods
        coef = np.polyfit(np.arange(frames.shape[0]) + 0.5 - 0.5 / n0, frames.mean(axis=1), deg)
        frames = frames - np.polyval(coef, t)
    return np.fft.rfft(frames, axis=1) / n0


def excited_lines(U: np.ndarray, threshold_db: float = EXCITATION_DB) -> np.ndarray:
    """Indices of the excited DFT lines of an averaged input spectrum ``U`` (DC never counts): lines whose
    amplitude is within ``threshold_db`` of the largest one."""
    a = np.abs(np.asarray(U))  # a new array: setting its DC entry leaves U alone
    a[0] = 0.0
    top = float(a.max()) if a.size else 0.0
    if top <= 0:
        raise DataError("periodic FRF: the input has no excited line (zero input?)")
    return np.flatnonzero(a >= top * 10.0 ** (-float(threshold_db) / 20.0))


def _mean_and_var(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean over axis 0 and the variance *of that mean* (sample variance / P); NaN variance for P = 1."""
    P = X.shape[0]
    m = X.mean(axis=0)
    if P < 2:
        return m, np.full(m.shape, np.nan)
    d = X - m
    return m, np.sum(np.abs(d) ** 2, axis=0) / (P - 1) / P


def frf_periodic(
    u: Any,
    y: Any,
    fs: float,
    periods: int,
    drop: int = 0,
    lines: Any = None,
    threshold_db: float = EXCITATION_DB,
    detrend: int = 1,
) -> FRF:
    r"""FRF of a periodic record (multisine) of ``periods`` periods, averaged per line over the periods.

    With :math:`U^{[p]}(k), Y^{[p]}(k)` the DFT of period ``p`` of the :math:`P'` periods used (Pintelon & Schoukens
    2012, eqs. 2-36/2-37, 2-40): :math:`\hat G(k) = \hat Y(k)/\hat U(k)` of the period means, with the sample
    variances :math:`\hat\sigma^2_{\hat Y} = \frac{1}{P'(P'-1)}\sum_p |Y^{[p]} - \hat Y|^2` (and of U, and their
    covariance) giving the first-order variance of :math:`\hat G` for correlated input and output noise (eq. 2-40).

    Parameters
    ----------
    u, y : array_like
        The record, exactly ``periods`` periods long.
    fs : float
        Sampling rate [Hz]; line ``k`` lies at ``k * fs / n0`` with ``n0`` samples per period.
    periods, drop : int
        Periods in the record, and leading periods left out (the transient of a start at rest).
    lines : array_like of int, optional
        Excited lines (e.g. ``info['excited_bins']`` of :func:`sysid.signals.multisine`); default: every line within
        ``threshold_db`` dB of the strongest input line.
    detrend : int
        Degree of the drift removed from u and y first (:func:`period_spectra`); 0: none.

    Returns
    -------
    FRF
        At the excited lines ``f_hz``, ``G``, ``std`` (of the complex G; NaN with one period), ``lines``; ``info``:
        ``period_samples``, ``periods_used``, ``var_Y``, ``var_U``.
    """
    u, y = _siso(u, y)
    fs = float(fs)
    U = period_spectra(u, periods, drop, detrend)
    Y = period_spectra(y, periods, drop, detrend)
    n0 = u.size // int(periods)
    Um, vU = _mean_and_var(U)
    Ym, vY = _mean_and_var(Y)
    Pu = U.shape[0]
    if Pu >= 2:
        cYU = np.sum((Y - Ym) * np.conj(U - Um), axis=0) / (Pu - 1) / Pu
    else:
        cYU = np.full(Um.shape, np.nan + 0j)
    if lines is None:
        k = excited_lines(Um, threshold_db)
    else:
        k = np.asarray(lines, dtype=np.int64).ravel()
        if k.size == 0 or k.min() < 1 or k.max() >= Um.size:
            raise ConfigError(f"periodic FRF: excited lines must lie in 1..{Um.size - 1}")
    G = Ym[k] / Um[k]
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = vY[k] / np.abs(Ym[k]) ** 2 + vU[k] / np.abs(Um[k]) ** 2 - 2.0 * np.real(cYU[k] / (Ym[k] * np.conj(Um[k])))
    var_G = np.abs(G) ** 2 * np.maximum(rel, 0.0)
    return FRF(
        f_hz=k * fs / n0,
        G=G,
        std=np.sqrt(var_G),
        lines=k,
        info={
            "method": "periodic (per-line average over periods)",
            "period_samples": n0,
            "periods": int(periods),
            "periods_used": int(Pu),
            "drop": int(drop),
            "detrend": int(detrend),
            "fs": fs,
            "var_Y": vY[k],
            "var_U": vU[k],
        },
    )
