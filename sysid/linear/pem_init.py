"""Initial estimates for the prediction-error models of :mod:`sysid.linear.pem` and polynomial helpers.

- :func:`sriv`: SISO B/F by the simplified refined instrumental-variable method (Ljung, *System Identification*,
  2nd ed., §7.6; Young, "Some observations on instrumental variable methods of time-series analysis", Int. J.
  Control 23, 1976): ARX least squares, then iterations with the data prefiltered by 1/F and the output lags
  instrumented by the model's own noise-free simulation; the iterate of least output-error cost is kept.
- :func:`hannan_rissanen`: ARMA D v = C e by a long AR model for the innovations, then least squares (Hannan &
  Rissanen, "Recursive estimation of mixed autoregressive-moving average order", Biometrika 69, 1982).
- :func:`stabilise`: reflect roots on or outside the unit circle (r → 1/r̄), Ljung §10.2 ("stable predictors").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.signal import lfilter

__all__ = ["sriv", "hannan_rissanen", "stabilise", "is_stable", "oe_sim", "shift", "lags"]

SRIV_ITERATIONS = 8
HR_AR_ORDER = 30  # long-AR order of the Hannan–Rissanen noise-model initialisation


def shift(x: np.ndarray, s: int) -> np.ndarray:
    """x(t − s) with zeros before the start (axis 0)."""
    if s <= 0:
        return x.copy()
    out = np.zeros_like(x)
    if s < x.shape[0]:
        out[s:] = x[:-s]
    return out


def lags(x: np.ndarray, which: Sequence[int]) -> np.ndarray:
    """Columns x(t − k) for k in ``which``."""
    return np.column_stack([shift(x, s) for s in which]) if len(which) else np.zeros((x.shape[0], 0))


def stabilise(poly: np.ndarray, margin: float = 1e-6) -> np.ndarray:
    """Monic polynomial in q⁻¹ with every root r, |r| ≥ 1, replaced by 1/r̄ (|r| = 1: pulled inside by ``margin``)."""
    poly = np.asarray(poly, float)
    if poly.size <= 1:
        return poly
    r = np.roots(poly)
    bad = np.abs(r) >= 1.0 - margin
    if not bad.any():
        return poly
    r = np.where(np.abs(r) > 1.0, 1.0 / np.conj(np.where(bad, r, 1.0)), r)
    mag = np.abs(r)
    r = np.where(mag >= 1.0 - margin, r / np.where(mag > 0, mag, 1.0) * (1.0 - margin), r)
    return np.real(np.poly(r))


def is_stable(poly: np.ndarray) -> bool:
    return poly.size <= 1 or bool(np.all(np.abs(np.roots(poly)) < 1.0))


def oe_sim(b: np.ndarray, f: np.ndarray, nk: int, u: np.ndarray) -> np.ndarray:
    return lfilter(np.concatenate([np.zeros(nk), b]), f, u)


def sriv(
    us: list[np.ndarray], ys: list[np.ndarray], nb: int, nf: int, nk: int, iterations: int = SRIV_ITERATIONS
) -> tuple[np.ndarray, np.ndarray]:
    """SISO B/F by the simplified refined instrumental-variable method (Ljung §7.6; Young 1976) on records
    (lists of 1-D arrays). Returns (b, f) with f monic and stable; the iterate of least output-error cost."""
    ulags = list(range(nk, nk + nb))
    ylags = list(range(1, nf + 1))

    def solve(uf, yf, xf):
        rows_P, rows_Z, rows_y = [], [], []
        L = max(ylags + ulags + [0])
        for u_, y_, x_ in zip(uf, yf, xf):
            P = np.hstack([-lags(y_, ylags), lags(u_, ulags)])[L:]
            Z = np.hstack([-lags(x_, ylags), lags(u_, ulags)])[L:] if x_ is not None else P
            rows_P.append(P)
            rows_Z.append(Z)
            rows_y.append(y_[L:])
        P, Z, yv = np.vstack(rows_P), np.vstack(rows_Z), np.concatenate(rows_y)
        th = np.linalg.lstsq(Z.T @ P, Z.T @ yv, rcond=None)[0]
        return th[nf:], np.concatenate([[1.0], th[:nf]])

    def cost(b, f):
        return sum(float(np.sum((y_ - oe_sim(b, f, nk, u_)) ** 2)) for u_, y_ in zip(us, ys))

    b, f = solve(us, ys, [None] * len(us))  # ARX least squares
    f = stabilise(f)
    best = (cost(b, f), b, f)
    if nf == 0:
        return b, f
    for _ in range(int(iterations)):
        uf = [lfilter([1.0], f, u_) for u_ in us]
        yf = [lfilter([1.0], f, y_) for y_ in ys]
        xf = [lfilter([1.0], f, oe_sim(b, f, nk, u_)) for u_ in us]
        try:
            b, f = solve(uf, yf, xf)
        except np.linalg.LinAlgError:  # pragma: no cover - singular instruments
            break
        f = stabilise(f)
        c = cost(b, f)
        if np.isfinite(c) and c < best[0]:
            best = (c, b, f)
    return best[1], best[2]


def hannan_rissanen(vs: list[np.ndarray], nc: int, nd: int) -> tuple[np.ndarray, np.ndarray]:
    """ARMA D v = C e by Hannan–Rissanen: long AR for ê, then least squares. Returns stable monic (c, d)."""
    if nc == 0 and nd == 0:
        return np.ones(1), np.ones(1)
    p = max(HR_AR_ORDER, 3 * (nc + nd))
    P = np.vstack([-lags(v, range(1, p + 1))[p:] for v in vs])
    a = np.linalg.lstsq(P, np.concatenate([v[p:] for v in vs]), rcond=None)[0]
    es = [lfilter(np.concatenate([[1.0], a]), [1.0], v) for v in vs]  # ê = A_long(q) v
    L = p + max(nc, nd)
    X = np.vstack([np.hstack([-lags(v, range(1, nd + 1)), lags(e, range(1, nc + 1))])[L:] for v, e in zip(vs, es)])
    th = np.linalg.lstsq(X, np.concatenate([(v - e)[L:] for v, e in zip(vs, es)]), rcond=None)[0]
    d = stabilise(np.concatenate([[1.0], th[:nd]]))
    c = stabilise(np.concatenate([[1.0], th[nd:]]))
    return c, d
