"""Compiled prediction of polynomial (N)ARX / (N)ARMAX models (dissertation §2.7, eq. 2-29 and the recursion after it).

A polynomial model is held in flat integer/float arrays so that one numba loop serves every model:

- a *signal matrix* ``Z`` of shape ``(N, n_y + n_u + n_e)``: columns ``[y_1..y_ny | u_1..u_nu | e_1..e_ne]``
  (``n_e`` is the number of noise channels, one per output, or 0 for NARX);
- per regressor ``r``: ``col[r]`` (column of ``Z``) and ``lag[r]`` (samples back);
- per output ``o``: ``terms[o, i, :]`` the regressor indices multiplied in term ``i`` (``-1`` pads), and
  ``theta[o, i]`` its parameter; ``n_terms[o]`` the count. A term with no factor is the constant.

Three predictions:

- :func:`one_step` — ŷ(t|t−1) from measured y; noise regressors e(t−j) are the one-step residuals computed
  on the way, e(t) = y(t) − ŷ(t|t−1) (eq. 2-16), zero before ``max_lag``;
- :func:`free_run` — eq. 2-29: the first ``max_lag`` samples are copied from the measurement, afterwards every
  output regressor is the model's own past output and noise regressors are zero;
- :func:`k_step` — a true k-step-ahead prediction at *every* sample t: the model starts at origin
  s = max(t−k+1, max_lag) from measured data before s (noise regressors from the one-step residuals) and runs
  free until t. ``k = 1`` is the one-step prediction, ``k ≥ N − max_lag`` is the free run (same arithmetic,
  bit-identical).

A free run that leaves ``[-bound, bound]`` or becomes non-finite is stopped: the rest is ``nan`` and the index
is returned (the identifier turns it into ``diverged_at_`` and a :class:`~sysid.errors.DivergenceWarning`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["one_step", "free_run", "k_step"]


@njit(cache=True, inline="always")
def _eval(o, W, t, terms, n_terms, theta, col, lag):
    """Model output ``o`` at row ``t`` of signal matrix ``W``: Σ_i θ_i Π_d W[t − lag, col] (eq. 2-7, 2-22)."""
    acc = 0.0
    max_deg = terms.shape[2]
    for i in range(n_terms[o]):
        v = theta[o, i]
        for d in range(max_deg):
            r = terms[o, i, d]
            if r < 0:
                break
            v *= W[t - lag[r], col[r]]
        acc += v
    return acc


@njit(cache=True)
def _one_step(Z, n_out, e_col0, has_e, L, terms, n_terms, theta, col, lag):
    N = Z.shape[0]
    yhat = np.empty((N, n_out))
    for t in range(min(L, N)):
        for o in range(n_out):
            yhat[t, o] = Z[t, o]
    for t in range(L, N):
        for o in range(n_out):
            yhat[t, o] = _eval(o, Z, t, terms, n_terms, theta, col, lag)
        if has_e:
            for o in range(n_out):
                Z[t, e_col0 + o] = Z[t, o] - yhat[t, o]
    return yhat


@njit(cache=True)
def _free_run(Z, n_out, L, terms, n_terms, theta, col, lag, bound):
    """Simulate in place in the y columns of Z (e columns must be zero). Returns the divergence index or -1."""
    N = Z.shape[0]
    for t in range(L, N):
        bad = False
        for o in range(n_out):
            v = _eval(o, Z, t, terms, n_terms, theta, col, lag)
            Z[t, o] = v
            if not (abs(v) <= bound):  # catches nan too
                bad = True
        if bad:
            for tt in range(t, N):
                for o in range(n_out):
                    Z[tt, o] = np.nan
            return t
    return -1


@njit(cache=True)
def _k_step(Z, n_out, e_col0, has_e, L, k, terms, n_terms, theta, col, lag, bound):
    """k-step-ahead at every sample. Z holds measured y, u and (if has_e) one-step residuals in the e columns."""
    N = Z.shape[0]
    ncol = Z.shape[1]
    yhat = np.empty((N, n_out))
    for t in range(min(L, N)):
        for o in range(n_out):
            yhat[t, o] = Z[t, o]
    first_bad = -1
    if N <= L:
        return yhat, first_bad
    W = np.empty((L + k, ncol))
    # origins s = L .. N-k; the prediction for t = s + k - 1 ends each window; the window from s = L also yields
    # every t < L + k - 1 (those have their origin clamped at L).
    last_origin = max(L, N - k)
    for s in range(L, last_origin + 1):
        steps = min(k, N - s)
        # copy rows s-L .. s+steps-1
        for j in range(L + steps):
            for c in range(ncol):
                W[j, c] = Z[s - L + j, c]
        for j in range(L, L + steps):
            for o in range(n_out):
                W[j, o] = 0.0
                if has_e:
                    W[j, e_col0 + o] = 0.0
        bad = False
        for j in range(L, L + steps):
            if not bad:
                for o in range(n_out):
                    v = _eval(o, W, j, terms, n_terms, theta, col, lag)
                    W[j, o] = v
                    if not (abs(v) <= bound):
                        bad = True
            if bad:
                for o in range(n_out):
                    W[j, o] = np.nan
            if s == L:
                t = j - L + s
                for o in range(n_out):
                    yhat[t, o] = W[j, o]
                if bad and first_bad < 0:
                    first_bad = t
        if s > L:
            t = s + steps - 1
            for o in range(n_out):
                yhat[t, o] = W[L + steps - 1, o]
            if bad and first_bad < 0:
                first_bad = t
    return yhat, first_bad


class CompiledModel:
    """Flat arrays of a polynomial model for the compiled loops (see module docstring)."""

    def __init__(self, n_out: int, n_in: int, has_e: bool, col, lag, terms, n_terms, theta, max_lag: int):
        self.n_out = int(n_out)
        self.n_in = int(n_in)
        self.has_e = bool(has_e)
        self.col = np.ascontiguousarray(col, dtype=np.int64)
        self.lag = np.ascontiguousarray(lag, dtype=np.int64)
        self.terms = np.ascontiguousarray(terms, dtype=np.int64)
        self.n_terms = np.ascontiguousarray(n_terms, dtype=np.int64)
        self.theta = np.ascontiguousarray(theta, dtype=np.float64)
        self.max_lag = int(max_lag)

    def signal_matrix(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        N = u.shape[0]
        ncol = self.n_out + self.n_in + (self.n_out if self.has_e else 0)
        Z = np.zeros((N, ncol))
        Z[:, : self.n_out] = y.reshape(N, -1)
        Z[:, self.n_out : self.n_out + self.n_in] = u.reshape(N, -1)
        return Z

    def _args(self):
        return self.terms, self.n_terms, self.theta, self.col, self.lag


def one_step(model: CompiledModel, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """One-step-ahead prediction ŷ(t|t−1) (N, n_out) and the residuals e (N, n_out) or None for NARX."""
    Z = model.signal_matrix(u, y)
    yhat = _one_step(Z, model.n_out, model.n_out + model.n_in, model.has_e, model.max_lag, *model._args())
    e = Z[:, model.n_out + model.n_in :].copy() if model.has_e else None
    return yhat, e


def free_run(model: CompiledModel, u: np.ndarray, y0: np.ndarray, bound: float = np.inf) -> tuple[np.ndarray, int]:
    """Free-run simulation (eq. 2-29). ``y0`` supplies the first ``max_lag`` samples (rest ignored).

    Returns (ŷ (N, n_out), divergence index or −1).
    """
    N = u.shape[0]
    y = np.zeros((N, model.n_out))
    L = min(model.max_lag, N)
    y[:L] = np.asarray(y0, dtype=float).reshape(-1, model.n_out)[:L]
    Z = model.signal_matrix(u, y)
    bad = _free_run(Z, model.n_out, model.max_lag, *model._args(), float(bound))
    return Z[:, : model.n_out].copy(), int(bad)


def k_step(model: CompiledModel, u: np.ndarray, y: np.ndarray, k: int, bound: float = np.inf) -> tuple[np.ndarray, int]:
    """k-step-ahead prediction at every sample (module docstring). Returns (ŷ (N, n_out), first bad index or −1)."""
    Z = model.signal_matrix(u, y)
    if model.has_e:
        _, e = one_step(model, u, y)
        Z[:, model.n_out + model.n_in :] = e
    N = Z.shape[0]
    k = int(min(k, max(N - model.max_lag, 1)))
    yhat, bad = _k_step(Z, model.n_out, model.n_out + model.n_in, model.has_e, model.max_lag, k, *model._args(),
                        float(bound))
    return yhat, int(bad)
