"""Best Linear Approximation (BLA) from multisine experiments and nonlinearity detection.

The *robust method* (Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*, 2nd ed.,
Wiley 2012, §3.7 / §4.3; Schoukens, Pintelon & Rolain, *Mastering System Identification in 100 Exercises*,
2012, §4.2): ``M`` realisations of a random-phase multisine, each measured over ``P`` periods (after the
transient), give per realisation ``m`` the period-averaged spectra :math:`\\hat U^{[m]}(k), \\hat Y^{[m]}(k)`,
the FRF :math:`\\hat G^{[m]} = \\hat Y^{[m]}/\\hat U^{[m]}` and its noise variance
:math:`\\hat\\sigma^2_{\\hat G^{[m]}}` from the period-to-period spread (:func:`sysid.linear.frf.frf_periodic`). Then

.. math::
    \\hat G_{BLA} = \\frac1M\\sum_m \\hat G^{[m]},\\qquad
    \\hat\\sigma^2_{BLA} = \\frac{1}{M(M-1)}\\sum_m |\\hat G^{[m]} - \\hat G_{BLA}|^2\\ \\text{(total)},\\qquad
    \\hat\\sigma^2_{BLA,n} = \\frac{1}{M^2}\\sum_m \\hat\\sigma^2_{\\hat G^{[m]}}\\ \\text{(noise)},

and the variance due to the stochastic nonlinear distortions is
:math:`\\hat\\sigma^2_{BLA,s} = \\hat\\sigma^2_{BLA} - \\hat\\sigma^2_{BLA,n}` (as a variance of
:math:`\\hat G_{BLA}`; the distortion level of one realisation is ``M`` times it). ``var_noise`` and
``var_distortion`` here are both variances *of the estimate* :math:`\\hat G_{BLA}`.

**Detection lines** (Pintelon & Schoukens 2012, §4.3.1 "fast method"): a multisine that excites only odd lines
leaves the even lines free — only even-degree nonlinearities put power there; leaving out some odd lines as
well (``detection_fraction`` of :func:`sysid.signals.multisine`) lets odd-degree nonlinearities show on them.
At those lines the output holds nonlinear distortion plus noise; the noise variance comes from the period
spread. The level is reported in dB over the noise floor, and a distortion is declared when the ratio
exceeds the ``1 - alpha`` quantile of its distribution under "noise only" (an F distribution with
:math:`2n` and :math:`2n(P-1)` degrees of freedom for ``n`` line-realisation pairs, Gaussian noise).
On a full grid (even lines excited) odd and even distortion fall on the same lines and cannot be told apart.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.stats

from sysid.errors import ConfigError, DataError
from sysid.linear.frf import EXCITATION_DB, _mean_and_var, excited_lines, period_spectra

__all__ = ["BLA", "best_linear_approximation", "detect_nonlinearity", "VERDICTS"]

VERDICTS = ("linear", "odd", "even", "odd+even")
#: numerical noise floor relative to the output amplitude at the excited lines (noise-free simulations)
_FLOOR_REL = 1e-10


@dataclass
class BLA:
    """Result of :func:`best_linear_approximation`; arrays are per excited line."""

    f_hz: np.ndarray
    G: np.ndarray
    var_noise: np.ndarray
    var_total: np.ndarray
    var_distortion: np.ndarray
    lines: np.ndarray
    nonlinearity: dict[str, Any]
    detection: dict[str, np.ndarray] = field(default_factory=dict)
    info: dict[str, Any] = field(default_factory=dict)


def _spectra(u: np.ndarray, y: np.ndarray, periods: int, drop: int, detrend: int):
    u = np.asarray(u, dtype=float)
    y = np.asarray(y, dtype=float)
    if u.ndim != 1 or y.ndim != 1 or u.size != y.size:
        raise DataError(f"BLA: 1-D u and y of equal length expected, got u{u.shape}, y{y.shape}")
    return period_spectra(u, periods, drop, detrend), period_spectra(y, periods, drop, detrend)


def best_linear_approximation(
    realisations: Sequence[tuple[Any, Any]],
    fs: float,
    periods: int,
    drop: int = 0,
    lines: Any = None,
    threshold_db: float = EXCITATION_DB,
    alpha: float = 1e-3,
    detrend: int = 1,
) -> BLA:
    """Robust BLA of ``M = len(realisations)`` multisine experiments of ``periods`` periods each.

    Parameters
    ----------
    realisations : sequence of (u, y)
        One pair of 1-D arrays per phase realisation, same length and period.
    fs : float
        Sampling rate [Hz].
    periods, drop : int
        Periods in each record and leading periods left out as transient; ``periods - drop >= 2`` for the noise
        variance and the detection-line test.
    lines : array_like of int, optional
        Excited lines (DFT indices of one period), one array or one per realisation; default: found per realisation
        within ``threshold_db`` of its strongest line. G_BLA is given at the lines excited in every realisation; each
        realisation's own non-excited lines are its detection lines.
    alpha : float
        False-alarm probability of the detection-line test.
    detrend : int
        Degree of the slow drift removed from u and y, fitted to the period means; 0: none (a drift raises every
        detection line).

    Returns
    -------
    BLA
        ``G``, ``var_noise``, ``var_total``, ``var_distortion`` (NaN when ``M == 1``) at ``f_hz``, ``nonlinearity``
        (:func:`detect_nonlinearity`), ``detection`` (per detection line) and ``info``.
    """
    if len(realisations) == 0:
        raise DataError("BLA: no realisation given")
    fs = float(fs)
    periods = int(periods)
    specs = [_spectra(u, y, periods, drop, detrend) for u, y in realisations]
    sizes = {S[0].shape[1] for S in specs}
    if len(sizes) != 1:
        raise DataError("BLA: the realisations have different period lengths")
    n0 = np.asarray(realisations[0][0]).size // periods
    Pu = specs[0][0].shape[0]
    means = [(_mean_and_var(U), _mean_and_var(Y), U, Y) for U, Y in specs]
    nl = means[0][0][0].size
    if lines is None:
        per = [excited_lines(m[0][0], threshold_db) for m in means]
    else:
        if isinstance(lines, (list, tuple)) and len(lines) == len(means) and all(np.ndim(x) == 1 for x in lines):
            per = [np.asarray(x, dtype=np.int64) for x in lines]
        else:
            per = [np.asarray(lines, dtype=np.int64).ravel()] * len(means)
        for kk in per:
            if kk.size == 0 or kk.min() < 1 or kk.max() >= nl:
                raise ConfigError(f"BLA: excited lines must lie in 1..{nl - 1}")
    k = per[0]
    for kj in per[1:]:
        k = np.intersect1d(k, kj)
    if k.size == 0:
        raise DataError("BLA: the realisations share no excited line")
    Gm, vGm = [], []
    for (Um, vU), (Ym, vY), U, Y in means:
        G = Ym[k] / Um[k]
        if Pu >= 2:
            cYU = np.sum((Y[:, k] - Ym[k]) * np.conj(U[:, k] - Um[k]), axis=0) / (Pu - 1) / Pu
            rel = (
                vY[k] / np.abs(Ym[k]) ** 2 + vU[k] / np.abs(Um[k]) ** 2 - 2.0 * np.real(cYU / (Ym[k] * np.conj(Um[k])))
            )
            vG = np.abs(G) ** 2 * np.maximum(rel, 0.0)
        else:
            vG = np.full(k.size, np.nan)
        Gm.append(G)
        vGm.append(vG)
    Gm_arr = np.array(Gm)
    M = Gm_arr.shape[0]
    G_bla = Gm_arr.mean(axis=0)
    var_noise = np.sum(np.array(vGm), axis=0) / M**2
    if M >= 2:
        var_total = np.sum(np.abs(Gm_arr - G_bla) ** 2, axis=0) / (M * (M - 1))
        var_dist = np.maximum(var_total - var_noise, 0.0)
    else:
        var_total = np.full(k.size, np.nan)
        var_dist = np.full(k.size, np.nan)
    Ym_all = np.array([m[1][0] for m in means])
    vY_all = np.array([m[1][1] for m in means])
    verdict, detection = detect_nonlinearity(Ym_all, vY_all, per, Pu, fs / n0, alpha=alpha)
    return BLA(
        f_hz=k * fs / n0,
        G=G_bla,
        var_noise=var_noise,
        var_total=var_total,
        var_distortion=var_dist,
        lines=k,
        nonlinearity=verdict,
        detection=detection,
        info={
            "method": "robust BLA (Pintelon & Schoukens 2012, §3.7)",
            "realisations": M,
            "periods": periods,
            "periods_used": Pu,
            "drop": int(drop),
            "detrend": int(detrend),
            "period_samples": int(n0),
            "fs": fs,
            "resolution_hz": fs / n0,
        },
    )


def detect_nonlinearity(
    Y: np.ndarray,
    var_Y: np.ndarray,
    excited: np.ndarray | Sequence[np.ndarray],
    periods_used: int,
    resolution_hz: float,
    alpha: float = 1e-3,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Odd / even nonlinear distortion levels at the detection lines.

    ``Y`` and ``var_Y`` are the period-averaged output spectra and the variances of those means, shape
    ``(M, n0//2 + 1)``; ``excited`` the excited lines (one array for all, or one per realisation). Detection lines are
    the non-excited lines from 1 up to the highest excited line: when every excited line is odd, the even ones carry
    even distortion and the odd ones odd distortion; otherwise all of them carry both (``classified`` False).

    Returns ``(nonlinearity, detection)``: ``nonlinearity`` = {``verdict``, ``odd_db``, ``even_db``,
    ``odd_detected``, ``even_detected``, ``classified``, ``threshold_db`` ...}; levels are
    ``10 log10(Σ|Y|² / Σσ²_Y)`` over the lines (and realisations) of a class, ``None`` without such lines.
    """
    Y = np.atleast_2d(Y)
    var_Y = np.atleast_2d(var_Y)
    M = Y.shape[0]
    if isinstance(excited, np.ndarray) and excited.ndim == 1 and excited.dtype.kind in "iu":
        excited = [excited] * M
    excited = [np.asarray(e, dtype=np.int64) for e in excited]
    if len(excited) != M:
        raise ConfigError(f"detect_nonlinearity: {len(excited)} excited-line sets for {M} realisations")
    classified = all(bool(np.all(e % 2 == 1)) for e in excited)
    names = ("odd", "even") if classified else ("any",)
    # per class: list over realisations of the detection lines
    classes: dict[str, list[np.ndarray]] = {n: [] for n in names}
    for e in excited:
        cand = np.setdiff1d(np.arange(1, int(e.max()) + 1), e)
        if classified:
            classes["odd"].append(cand[cand % 2 == 1])
            classes["even"].append(cand[cand % 2 == 0])
        else:
            classes["any"].append(cand)
    # numerical floor: a noise-free simulation has var_Y ≈ 0; its round-off sits near 1e-16 of the signal
    ref = float(np.sqrt(np.mean([np.mean(np.abs(Y[m, e]) ** 2) for m, e in enumerate(excited)])))
    floor = (_FLOOR_REL * ref) ** 2
    vY = np.maximum(var_Y, floor)
    out: dict[str, Any] = {"classified": classified, "alpha": alpha}
    det_f, det_kind, det_level, det_noise = [], [], [], []
    levels: dict[str, tuple[float | None, bool, float | None]] = {}
    count = {}
    for name, per in classes.items():
        n = int(sum(lines.size for lines in per))
        count[name] = n
        if n == 0 or periods_used < 2:
            levels[name] = (None, False, None)
            continue
        S = float(sum(np.sum(np.abs(Y[m, lines]) ** 2) for m, lines in enumerate(per)))
        N = float(sum(np.sum(vY[m, lines]) for m, lines in enumerate(per)))
        crit = float(scipy.stats.f.ppf(1.0 - alpha, 2 * n, 2 * n * (periods_used - 1)))
        ratio = S / N
        levels[name] = (10.0 * np.log10(max(ratio, 1e-300)), bool(ratio > crit), 10.0 * np.log10(crit))
        for m, lines in enumerate(per):
            det_f.append(lines * resolution_hz)
            det_kind += [name] * lines.size
            det_level.append(np.abs(Y[m, lines]) ** 2)
            det_noise.append(vY[m, lines])
    if classified:
        odd_db, odd_det, odd_thr = levels["odd"]
        even_db, even_det, even_thr = levels["even"]
        notes = []
        if count["odd"] == 0:
            notes.append("no odd detection lines (design the multisine with detection_fraction > 0)")
    else:
        odd_db, odd_det, odd_thr = levels["any"]
        even_db, even_det, even_thr = levels["any"]
        notes = [
            "even lines are excited (full grid): odd and even distortion fall on the same detection lines "
            "and cannot be told apart; use an odd (or odd-odd) grid"
        ]
    if periods_used < 2:
        notes.append("fewer than 2 periods used: no noise estimate, no detection")
    verdict = {(False, False): "linear", (True, False): "odd", (False, True): "even", (True, True): "odd+even"}[
        (odd_det, even_det)
    ]
    out.update(
        verdict=verdict,
        odd_db=odd_db,
        even_db=even_db,
        odd_detected=odd_det,
        even_detected=even_det,
        odd_threshold_db=odd_thr,
        even_threshold_db=even_thr,
        odd_lines=count.get("odd", count.get("any")),
        even_lines=count.get("even", count.get("any")),
        notes=notes,
    )
    detection = {
        "f_hz": np.concatenate(det_f) if det_f else np.empty(0),
        "kind": np.array(det_kind),
        "level": np.concatenate(det_level) if det_level else np.empty(0),
        "noise": np.concatenate(det_noise) if det_noise else np.empty(0),
    }
    return out, detection
