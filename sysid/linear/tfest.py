"""Discrete-time transfer function fitted to a nonparametric FRF (a ``tfest``-like frequency-domain fit).

Model (``q`` the shift operator, ``nk`` the delay in samples, MATLAB's ``tfest``/``oe`` names):

.. math::
    G(z) = \\frac{B(z)}{A(z)} = \\frac{b_0 z^{-n_k} + b_1 z^{-n_k-1} + \\dots + b_{n_b-1} z^{-n_k-n_b+1}}
    {1 + a_1 z^{-1} + \\dots + a_{n_a} z^{-n_a}}

fitted to FRF samples :math:`G_k` at :math:`z_k = e^{j2\\pi f_k/f_s}` by the weighted nonlinear least-squares
criterion :math:`V(\\theta) = \\sum_k W_k |G_k - B(z_k)/A(z_k)|^2`.

1. Start: Levy's linearisation :math:`\\sum W_k|A G_k - B|^2` (Levy 1959), then Sanathanan–Koerner iterations
   that divide by the previous denominator, :math:`\\sum W_k |A^{(i)} G_k - B^{(i)}|^2 / |A^{(i-1)}|^2`
   (Sanathanan & Koerner, IEEE TAC 8, 1963; Pintelon & Schoukens 2012, §9.3 / §9.4).
2. Refinement: Gauss–Newton / Levenberg–Marquardt on :math:`V(\\theta)` itself
   (:func:`scipy.optimize.least_squares`).
3. Stability: poles outside the unit circle are reflected inside (:math:`p \\to 1/\\bar p`, same magnitude
   response up to a constant), and ``B`` is refitted linearly for that ``A``.

With :math:`W_k = S_{uu}(f_k)` (the input power spectrum) the criterion is the frequency-domain form of the
output-error criterion of a simulation model (Ljung, *System Identification*, 2nd ed., eq. 8.71), which is
what a free-run simulation error measures.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.optimize
import scipy.signal

from sysid.errors import ConfigError, DataError

__all__ = ["TransferFunction", "tfest"]


@dataclass
class TransferFunction:
    """A fitted discrete-time transfer function in :func:`scipy.signal.lfilter` convention (``b`` includes
    the ``nk`` leading zeros; ``a[0] == 1``) at sampling rate ``fs`` [Hz]."""

    b: np.ndarray
    a: np.ndarray
    fs: float
    info: dict[str, Any] = field(default_factory=dict)

    def frequency_response(self, f_hz: Any) -> np.ndarray:
        """Complex response at ``f_hz`` [Hz] (:func:`scipy.signal.freqz`)."""
        _, h = scipy.signal.freqz(self.b, self.a, worN=np.asarray(f_hz, dtype=float), fs=self.fs)
        return h

    def simulate(self, u: Any) -> np.ndarray:
        """Free-run output for the input samples ``u`` from rest (:func:`scipy.signal.lfilter`)."""
        return scipy.signal.lfilter(self.b, self.a, np.asarray(u, dtype=float))

    @property
    def poles(self) -> np.ndarray:
        return np.roots(self.a)


def _basis(z_inv: np.ndarray, n: int, start: int = 0) -> np.ndarray:
    """Columns z^{-(start)}, z^{-(start+1)}, ..., z^{-(start+n-1)} at the points (complex, (K, n))."""
    return z_inv[:, None] ** (start + np.arange(n))[None, :]


def _ls_complex(Phi: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Real θ minimising ||Phi θ - rhs||² for complex Phi, rhs (stacked real and imaginary parts)."""
    A = np.vstack([Phi.real, Phi.imag])
    r = np.concatenate([rhs.real, rhs.imag])
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    theta, *_ = np.linalg.lstsq(A / scale, r, rcond=None)
    return theta / scale


def _stabilise(a: np.ndarray) -> tuple[np.ndarray, int]:
    p = np.roots(a)
    bad = np.abs(p) >= 1.0
    if not bad.any():
        return a, 0
    p[bad] = 1.0 / np.conj(p[bad]) * 0.999 ** (np.abs(p[bad]) == 1.0)
    return np.real(np.poly(p)), int(bad.sum())


def tfest(
    f_hz: Any,
    G: Any,
    fs: float,
    nb: int,
    na: int,
    nk: int = 0,
    weight: Any = None,
    iterations: int = 20,
    refine: bool = True,
    var: Any = None,
) -> TransferFunction:
    r"""Fit ``B(z)/A(z)`` (``nb`` numerator coefficients after ``nk`` delays, ``na`` poles) to FRF data.

    Parameters
    ----------
    f_hz, G : array_like
        Frequencies [Hz] (0 <= f < fs/2) and complex FRF values; non-finite points are ignored.
    fs : float
        Sampling rate [Hz] of the model.
    nb, na, nk : int
        Numerator coefficients (>= 1), denominator order (>= 0), input delay in samples (>= 0).
    weight : array_like, optional
        Non-negative weights :math:`W_k` (e.g. the input power spectrum, or ``1/var(G)``); default 1.
    iterations, refine : int, bool
        Sanathanan–Koerner iterations after Levy's start; then minimise the weighted nonlinear criterion
        (:func:`scipy.optimize.least_squares`).
    var : array_like, optional
        Variance of each (circular, independent) FRF value, e.g. a BLA's ``var_total``: the parameters' covariance
        by the sandwich :math:`H^{-1} J^T \Sigma J H^{-1}` (Pintelon & Schoukens 2012, §7.2) in ``info['cov']``
        (order ``a_1..a_na, b_0..b_{nb-1}``), ``info['std_a']``, ``info['std_b']``; None when poles were reflected.

    Returns
    -------
    TransferFunction
        ``b`` (length ``nk + nb``), ``a`` (length ``na + 1``), ``info`` with ``cost`` (weighted criterion over the
        sum of the weights), ``reflected_poles`` and the orders.
    """
    f = np.asarray(f_hz, dtype=float).ravel()
    G = np.asarray(G, dtype=complex).ravel()
    if f.size != G.size:
        raise DataError(f"tfest: {f.size} frequencies but {G.size} FRF values")
    w = np.ones(f.size) if weight is None else np.asarray(weight, dtype=float).ravel()
    if w.size != f.size:
        raise DataError(f"tfest: {w.size} weights for {f.size} frequencies")
    fs = float(fs)
    nb, na, nk = int(nb), int(na), int(nk)
    if nb < 1 or na < 0 or nk < 0:
        raise ConfigError(f"tfest: need nb >= 1, na >= 0, nk >= 0 (got nb={nb}, na={na}, nk={nk})")
    ok = np.isfinite(f) & np.isfinite(G) & np.isfinite(w) & (w > 0) & (f >= 0) & (f < fs / 2 + 1e-9 * fs)
    f, G, w = f[ok], G[ok], w[ok]
    if 2 * f.size < nb + na:
        raise DataError(f"tfest: {f.size} usable frequencies cannot determine {nb + na} parameters")
    sw = np.sqrt(w / w.max())
    z_inv = np.exp(-2j * np.pi * f / fs)
    Za = _basis(z_inv, na, 1)  # z^-1 .. z^-na
    Zb = _basis(z_inv, nb, nk)  # z^-nk .. z^-(nk+nb-1)

    def split(theta):
        return theta[:na], theta[na:]

    def evalAB(theta):
        a, b = split(theta)
        return 1.0 + Za @ a, Zb @ b

    # Levy (first pass, |A_prev| = 1) then Sanathanan–Koerner
    den = np.ones(f.size)
    theta = np.zeros(na + nb)
    for _ in range(max(1, int(iterations) + 1)):
        s = sw / den
        Phi = np.hstack([Za * (G * s)[:, None], -Zb * s[:, None]])
        theta = _ls_complex(Phi, -G * s)
        A, _ = evalAB(theta)
        den = np.maximum(np.abs(A), 1e-12)

    def residual(theta):
        A, B = evalAB(theta)
        e = sw * (G - B / A)
        return np.concatenate([e.real, e.imag])

    if refine and theta.size:
        sol = scipy.optimize.least_squares(
            residual,
            theta,
            method="lm" if 2 * f.size >= theta.size else "trf",
            xtol=1e-12,
            ftol=1e-12,
            max_nfev=200 * (theta.size + 1),
        )
        if np.all(np.isfinite(sol.x)) and np.sum(sol.fun**2) <= np.sum(residual(theta) ** 2):
            theta = sol.x
    cov = None
    if var is not None:
        v = np.asarray(var, dtype=float).ravel()
        if v.size != ok.size:
            raise DataError(f"tfest: {v.size} variances for {ok.size} frequencies")
        v = v[ok]
        A, B = evalAB(theta)
        dM = np.hstack([-(B / A**2)[:, None] * Za, Zb / A[:, None]])  # dM/da_i, dM/db_i
        J = -sw[:, None] * dM
        J = np.vstack([J.real, J.imag])
        sig = np.concatenate([sw**2 * v / 2.0] * 2)
        Hinv = np.linalg.pinv(J.T @ J)
        cov = Hinv @ (J.T * sig) @ J @ Hinv
    a_poly = np.concatenate([[1.0], theta[:na]])
    a_poly, n_reflected = _stabilise(a_poly)
    b_coef = theta[na:]
    if n_reflected:  # B for the stabilised A: linear least squares of sw·(G − B/A)
        A = _basis(z_inv, na + 1, 0) @ a_poly
        b_coef = _ls_complex(Zb * (sw / A)[:, None], G * sw)
    b_poly = np.concatenate([np.zeros(nk), b_coef])
    _, h = scipy.signal.freqz(b_poly, a_poly, worN=f, fs=fs)
    cost = float(np.sum(w * np.abs(G - h) ** 2) / np.sum(w))
    info_cov: dict[str, Any] = {}
    if cov is not None and not n_reflected:
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
        info_cov = {"cov": cov, "std_a": sd[:na], "std_b": sd[na:]}
    return TransferFunction(
        b=b_poly,
        a=a_poly,
        fs=fs,
        info={
            **info_cov,
            "nb": nb,
            "na": na,
            "nk": nk,
            "cost": cost,
            "reflected_poles": n_reflected,
            "points": int(f.size),
            "method": "Levy + Sanathanan-Koerner" + (" + nonlinear LS" if refine else ""),
        },
    )
