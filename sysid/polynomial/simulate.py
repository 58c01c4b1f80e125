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
- :func:`k_step` — k steps ahead at *every* sample t: from measured data before s = max(t−k+1, max_lag) (noise
  regressors from the one-step residuals), free until t; k = 1 is one-step, k ≥ N − max_lag the free run.

Speed: the terms of each output are grouped as [input-only | output-dependent | noise] (the parameters'
order inside the model is unchanged). The input-only part cannot feed back, so it is computed for all samples
in one independent (vectorisable) loop first; the recursion then evaluates only the output-dependent terms
(and, for one-step and k-step, the noise terms; in a free run they are zero and skipped). Every mode adds the
groups in the same order, so k = N reproduces the free run bit for bit.

A free run that leaves ``[-bound, bound]`` or becomes non-finite is stopped: the rest is ``nan`` and the index
is returned (the identifier turns it into ``diverged_at_`` and a :class:`~sysid.errors.DivergenceWarning`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["one_step", "free_run", "k_step"]


@njit(cache=True, inline="always")
def _eval(o, W, t, fac, theta, i0, i1, ncol):
    """Σ_{i0 ≤ i < i1} θ_i Π_d W[t·ncol + fac[o, i, d]] for output ``o`` at row ``t`` of the flat signal matrix
    (eq. 2-7, 2-22). ``fac`` holds flat offsets −lag·ncol + col; unused factors point at the ones column, so
    the loop has no branch."""
    acc = 0.0
    base = t * ncol
    D = fac.shape[2]
    if D == 2:  # the common degree-2 case, unrolled
        for i in range(i0, i1):
            acc += theta[o, i] * W[base + fac[o, i, 0]] * W[base + fac[o, i, 1]]
        return acc
    if D == 1:
        for i in range(i0, i1):
            acc += theta[o, i] * W[base + fac[o, i, 0]]
        return acc
    for i in range(i0, i1):
        v = theta[o, i]
        for d in range(D):
            v *= W[base + fac[o, i, d]]
        acc += v
    return acc


@njit(cache=True)
def _exogenous(Z, L, fac, theta, n_exo):
    """The input-only part of every output at every sample t ≥ L (no recursion: an independent loop)."""
    N, ncol = Z.shape
    n_out = n_exo.shape[0]
    W = Z.reshape(N * ncol)
    x = np.zeros((N, n_out))
    for t in range(L, N):
        for o in range(n_out):
            x[t, o] = _eval(o, W, t, fac, theta, 0, n_exo[o], ncol)
    return x


@njit(cache=True)
def _one_step(Z, x, n_out, e_col0, has_e, L, fac, theta, n_exo, n_dyn, n_terms):
    N, ncol = Z.shape
    W = Z.reshape(N * ncol)
    yhat = np.empty((N, n_out))
    for t in range(min(L, N)):
        for o in range(n_out):
            yhat[t, o] = Z[t, o]
    for t in range(L, N):
        for o in range(n_out):
            v = x[t, o] + _eval(o, W, t, fac, theta, n_exo[o], n_exo[o] + n_dyn[o], ncol)
            if n_terms[o] > n_exo[o] + n_dyn[o]:
                v += _eval(o, W, t, fac, theta, n_exo[o] + n_dyn[o], n_terms[o], ncol)
            yhat[t, o] = v
        if has_e:
            for o in range(n_out):
                Z[t, e_col0 + o] = Z[t, o] - yhat[t, o]
    return yhat


@njit(cache=True)
def _free_run(Z, x, n_out, L, fac, theta, n_exo, n_dyn, bound):
    """Simulate in place in the y columns of Z (noise terms are zero and skipped).

    Returns the divergence index or -1."""
    N, ncol = Z.shape
    W = Z.reshape(N * ncol)
    for t in range(L, N):
        bad = False
        for o in range(n_out):
            v = x[t, o] + _eval(o, W, t, fac, theta, n_exo[o], n_exo[o] + n_dyn[o], ncol)
            W[t * ncol + o] = v
            if not (abs(v) <= bound):  # catches nan too
                bad = True
        if bad:
            for tt in range(t, N):
                for o in range(n_out):
                    Z[tt, o] = np.nan
            return t
    return -1


@njit(cache=True)
def _k_step(Z, x, n_out, e_col0, has_e, L, k, fac, theta, n_exo, n_dyn, n_terms, bound):
    """k-step-ahead at every sample. Z holds measured y, u and (if has_e) one-step residuals in the e columns."""
    N, ncol = Z.shape
    yhat = np.empty((N, n_out))
    for t in range(min(L, N)):
        for o in range(n_out):
            yhat[t, o] = Z[t, o]
    first_bad = -1
    if N <= L:
        return yhat, first_bad
    W2 = np.empty((L + k, ncol))
    W = W2.reshape((L + k) * ncol)
    # origins s = L .. N-k; the prediction for t = s + k - 1 ends each window; the window from s = L also yields
    # every t < L + k - 1 (those have their origin clamped at L).
    last_origin = max(L, N - k)
    for s in range(L, last_origin + 1):
        steps = min(k, N - s)
        for j in range(L + steps):
            for c in range(ncol):
                W2[j, c] = Z[s - L + j, c]
        for j in range(L, L + steps):
            for o in range(n_out):
                W2[j, o] = 0.0
                if has_e:
                    W2[j, e_col0 + o] = 0.0
        bad = False
        for j in range(L, L + steps):
            if not bad:
                for o in range(n_out):
                    v = x[s - L + j, o] + _eval(o, W, j, fac, theta, n_exo[o], n_exo[o] + n_dyn[o], ncol)
                    if n_terms[o] > n_exo[o] + n_dyn[o]:
                        v += _eval(o, W, j, fac, theta, n_exo[o] + n_dyn[o], n_terms[o], ncol)
                    W2[j, o] = v
                    if not (abs(v) <= bound):
                        bad = True
            if bad:
                for o in range(n_out):
                    W2[j, o] = np.nan
            if s == L:
                t = j - L + s
                for o in range(n_out):
                    yhat[t, o] = W2[j, o]
                if bad and first_bad < 0:
                    first_bad = t
        if s > L:
            t = s + steps - 1
            for o in range(n_out):
                yhat[t, o] = W2[L + steps - 1, o]
            if bad and first_bad < 0:
                first_bad = t
    return yhat, first_bad


class CompiledModel:
    """Flat arrays of a polynomial model for the compiled loops (see module docstring).

    ``terms[o, i, :]`` regressor indices (−1 pads) and ``theta[o, i]`` for output o; ``kinds[r]`` is "y", "u" or
    "e" for regressor r (used to group the terms).
    """

    def __init__(self, n_out: int, n_in: int, has_e: bool, col, lag, terms, n_terms, theta, max_lag: int, kinds=None):
        self.n_out = int(n_out)
        self.n_in = int(n_in)
        self.has_e = bool(has_e)
        self.col = np.ascontiguousarray(col, dtype=np.int64)
        self.lag = np.ascontiguousarray(lag, dtype=np.int64)
        terms = np.asarray(terms, dtype=np.int64)
        theta = np.asarray(theta, dtype=np.float64)
        n_terms = np.asarray(n_terms, dtype=np.int64)
        kinds = list(kinds) if kinds is not None else ["y"] * len(self.col)
        # group the terms of each output: input-only (and constant), output-dependent, noise
        T = terms.shape[1]
        g_terms = -np.ones_like(terms)
        g_theta = np.zeros_like(theta)
        self.n_exo = np.zeros(self.n_out, dtype=np.int64)
        self.n_dyn = np.zeros(self.n_out, dtype=np.int64)
        for o in range(self.n_out):
            groups: tuple[list[int], list[int], list[int]] = ([], [], [])
            for i in range(int(n_terms[o])):
                ks = {kinds[r] for r in terms[o, i] if r >= 0}
                groups[2 if "e" in ks else (1 if "y" in ks else 0)].append(i)
            order = groups[0] + groups[1] + groups[2]
            g_terms[o, : len(order)] = terms[o, order]
            g_theta[o, : len(order)] = theta[o, order]
            self.n_exo[o], self.n_dyn[o] = len(groups[0]), len(groups[1])
        del T
        self.terms = np.ascontiguousarray(g_terms)
        self.theta = np.ascontiguousarray(g_theta)
        self.n_terms = np.ascontiguousarray(n_terms)
        self.max_lag = int(max_lag)
        # flat offsets: factor r of a term reads Z[t − lag_r, col_r] = Zflat[t·ncol − lag_r·ncol + col_r]; padding
        # (−1) reads the trailing ones column of the same row.
        self.ncol = self.n_out + self.n_in + (self.n_out if self.has_e else 0) + 1
        off = np.append(-self.lag * self.ncol + self.col, self.ncol - 1)
        self.fac = np.ascontiguousarray(off[np.where(self.terms < 0, off.size - 1, self.terms)], dtype=np.int64)

    def signal_matrix(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        N = u.shape[0]
        Z = np.empty((N, self.ncol))
        Z[:, : self.n_out] = y.reshape(N, -1)
        Z[:, self.n_out : self.n_out + self.n_in] = u.reshape(N, -1)
        Z[:, self.n_out + self.n_in : -1] = 0.0
        Z[:, -1] = 1.0
        return Z

    def exogenous(self, Z: np.ndarray) -> np.ndarray:
        return _exogenous(Z, self.max_lag, self.fac, self.theta, self.n_exo)


def one_step(model: CompiledModel, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """One-step-ahead prediction ŷ(t|t−1) (N, n_out) and the residuals e (N, n_out) or None for NARX."""
    Z = model.signal_matrix(u, y)
    x = model.exogenous(Z)
    yhat = _one_step(
        Z,
        x,
        model.n_out,
        model.n_out + model.n_in,
        model.has_e,
        model.max_lag,
        model.fac,
        model.theta,
        model.n_exo,
        model.n_dyn,
        model.n_terms,
    )
    e = Z[:, model.n_out + model.n_in : model.ncol - 1].copy() if model.has_e else None
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
    x = model.exogenous(Z)
    bad = _free_run(Z, x, model.n_out, model.max_lag, model.fac, model.theta, model.n_exo, model.n_dyn, float(bound))
    return Z[:, : model.n_out].copy(), int(bad)


def k_step(model: CompiledModel, u: np.ndarray, y: np.ndarray, k: int, bound: float = np.inf) -> tuple[np.ndarray, int]:
    """k-step-ahead prediction at every sample (module docstring). Returns (ŷ (N, n_out), first bad index or −1)."""
    Z = model.signal_matrix(u, y)
    if model.has_e:
        _, e = one_step(model, u, y)
        Z[:, model.n_out + model.n_in : model.ncol - 1] = e
    x = model.exogenous(Z)
    N = Z.shape[0]
    k = int(min(k, max(N - model.max_lag, 1)))
    yhat, bad = _k_step(
        Z,
        x,
        model.n_out,
        model.n_out + model.n_in,
        model.has_e,
        model.max_lag,
        k,
        model.fac,
        model.theta,
        model.n_exo,
        model.n_dyn,
        model.n_terms,
        float(bound),
    )
    return yhat, int(bad)
