"""A wavelet-network NARX for Table 5.2's NARX lines, in the manner of MATLAB's ``idnlarx`` with a ``wavenet``
nonlinearity (Table 5.1: "Non-linearity estimator: Sigmoid or Wavelet network").

The one-step predictor is (Zhang 1997, eq. 2; the System Identification Toolbox's ``wavenet``):

    ŷ(t) = (x − r)ᵀ L + Σ_i a_i κ(b_i (x − r) − c_i) + d,    κ(s) = (m − sᵀs) exp(−sᵀs / 2),

with x the regressor [y(t−1) … y(t−n_y), u(t−n_k) … u(t−n_k−n_u+1)] scaled to unit variance (r its mean), κ the
radial "Mexican hat" wavelet in m = n_y + n_u dimensions, and the unit count ``units`` (Table 5.1: 4, 5 or 10).

Estimation is the non-iterative one Zhang describes for wavelet networks: candidate wavelets centred on regressor
samples of the data at three dilations (set from the data's spread so that κ's zero crossing lies at ¼, 1 and 4
times the median squared distance), the ``units`` of them that most reduce what the linear term leaves chosen by
orthogonal forward regression, then L, a and d together by least squares. MATLAB refines that start by
prediction-error minimisation of all parameters; this does not (the page says so).

Q. Zhang, "Using wavelet network in nonparametric estimation", IEEE Trans. Neural Networks 8(2), 1997.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["WaveletNARX"]

#: free-run divergence bound, in multiples of the largest measured |y| (as the project's other identifiers)
_BOUND = 1e3


class WaveletNARX:
    """Wavelet-network NARX (``fit(record)`` returns self; ``predict(record, horizon)`` with 1 or None)."""

    name = "wavenet"

    def __init__(
        self,
        ny: int,
        nu: int,
        nk: int = 1,
        units: int = 10,
        n_centres: int = 200,
        spreads: tuple[float, ...] = (0.25, 1.0, 4.0),
        seed: int = 0,
    ):
        self.ny = ny
        self.nu = nu
        self.nk = nk
        self.units = units
        self.n_centres = n_centres
        self.spreads = spreads
        self.seed = seed

    # ------------------------------------------------------------------ regressors and units
    def _regressors(self, u: np.ndarray, y: np.ndarray, times: np.ndarray) -> np.ndarray:
        ylags = y[times[:, None] - np.arange(1, self.ny + 1)[None, :]]
        ulags = u[times[:, None] - np.arange(self.nk, self.nk + self.nu)[None, :]]
        return np.hstack([ylags, ulags])

    def _kappa(self, z: np.ndarray, centres: np.ndarray, dil: np.ndarray) -> np.ndarray:
        """κ(b_i (z − c_i)) for every row of ``z`` (n × m) and unit i (columns)."""
        d2 = np.sum(z * z, axis=1)[:, None] - 2.0 * z @ centres.T + np.sum(centres * centres, axis=1)[None, :]
        s2 = np.maximum(d2, 0.0) * dil[None, :] ** 2
        return (z.shape[1] - s2) * np.exp(-0.5 * s2)

    def _design(self, z: np.ndarray) -> np.ndarray:
        return np.hstack([z, np.ones((z.shape[0], 1)), self._kappa(z, self.centres_, self.dilations_)])

    # ------------------------------------------------------------------ estimation
    def fit(self, rec) -> WaveletNARX:
        u, y = np.asarray(rec.u, dtype=float).ravel(), np.asarray(rec.output, dtype=float).ravel()
        lag = max(self.ny, self.nk + self.nu - 1)
        times = np.arange(lag, len(y))
        x = self._regressors(u, y, times)
        self.r_, self.scale_ = x.mean(axis=0), np.maximum(x.std(axis=0), 1e-300)
        z = (x - self.r_) / self.scale_
        target = y[times]
        m = z.shape[1]
        rng = np.random.default_rng(self.seed)
        cand_c = z[rng.choice(len(z), size=min(self.n_centres, len(z)), replace=False)]
        # median squared distance between data rows and candidate centres (a sample of each)
        rows = z[rng.choice(len(z), size=min(500, len(z)), replace=False)]
        dist2 = float(np.median(np.sum((rows[:, None, :] - cand_c[None, :50, :]) ** 2, axis=2)))
        # κ's zero crossing is at sᵀs = m: dilation b with b² · spread · median d² = m
        cand_b = np.concatenate([np.full(len(cand_c), np.sqrt(m / (q * dist2))) for q in self.spreads])
        cand_c = np.tile(cand_c, (len(self.spreads), 1))
        lin = np.hstack([z, np.ones((len(z), 1))])
        q_basis, _ = np.linalg.qr(lin)
        resid = target - q_basis @ (q_basis.T @ target)
        cols = self._kappa(z, cand_c, cand_b)
        chosen: list[int] = []
        for _ in range(min(self.units, cols.shape[1])):
            perp = cols - q_basis @ (q_basis.T @ cols)
            norm2 = np.sum(perp * perp, axis=0)
            ok = norm2 > 1e-12 * max(float(norm2.max()), 1e-300)
            score = np.where(ok, (perp.T @ resid) ** 2 / np.maximum(norm2, 1e-300), -1.0)
            score[chosen] = -1.0
            j = int(np.argmax(score))
            if score[j] <= 0.0:
                break
            chosen.append(j)
            v = perp[:, j] / np.sqrt(norm2[j])
            q_basis = np.hstack([q_basis, v[:, None]])
            resid = resid - v * (v @ resid)
        self.centres_, self.dilations_ = cand_c[chosen], cand_b[chosen]
        self.theta_ = np.linalg.lstsq(self._design(z), target, rcond=None)[0]
        self.max_lag_ = lag
        self.n_parameters_ = int(self.theta_.size + self.centres_.size + self.dilations_.size)
        self.y_bound_ = _BOUND * max(float(np.max(np.abs(y))), 1e-300)
        return self

    # ------------------------------------------------------------------ prediction
    def predict(self, rec, horizon: int | None = 1) -> np.ndarray:
        """One-step prediction (``horizon=1``) or free-run simulation (``None``) from the first ``max_lag_``
        measured outputs; a free run leaving ± 1000 × the largest fitted |y| is NaN from there on."""
        u, y = np.asarray(rec.u, dtype=float).ravel(), np.asarray(rec.output, dtype=float).ravel()
        lag = self.max_lag_
        out = y.astype(float).copy()
        if horizon == 1:
            times = np.arange(lag, len(y))
            out[lag:] = self._design((self._regressors(u, y, times) - self.r_) / self.scale_) @ self.theta_
            return out
        if horizon is not None:
            raise ValueError("wavenet: horizon must be 1 or None (free run)")
        sim = out
        for t in range(lag, len(y)):
            x = self._regressors(u, sim, np.array([t]))
            sim[t] = float((self._design((x - self.r_) / self.scale_) @ self.theta_)[0])
            if not abs(sim[t]) <= self.y_bound_:
                sim[t:] = np.nan
                break
        return sim

    def settings(self) -> dict[str, Any]:
        return {
            "ny": self.ny,
            "nu": self.nu,
            "nk": self.nk,
            "units": self.units,
            "n_centres": self.n_centres,
            "spreads": list(self.spreads),
            "seed": self.seed,
        }
