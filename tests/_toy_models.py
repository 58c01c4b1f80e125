"""Test doubles for the scoring tests: a tiny least-squares ARX and a deliberately degraded copy.

They implement the Identifier interface (sysid.base) so scoring can be tested before/independently of the
real identifiers; they are not product identifiers.
"""

from __future__ import annotations

import numpy as np

from sysid.base import Identifier, as_record_list


class ToyARX(Identifier):
    name = "toy-arx"

    def __init__(self, ny: int = 2, nu: int = 2, degrade: float = 0.0):
        self.ny, self.nu, self.degrade = ny, nu, degrade

    def _regressors(self, y, u):
        n = max(self.ny, self.nu)
        cols = [y[n - k : len(y) - k] for k in range(1, self.ny + 1)] + [
            u[n - k : len(u) - k] for k in range(1, self.nu + 1)
        ]
        return np.column_stack(cols + [np.ones(len(y) - n)]), y[n:]

    def fit(self, data):
        X, T = zip(*(self._regressors(r.y, r.u) for r in as_record_list(data)))
        self.theta_ = np.linalg.lstsq(np.vstack(X), np.concatenate(T), rcond=None)[0]
        self.max_lag_ = max(self.ny, self.nu)
        self.n_parameters_ = self.theta_.size
        return self

    def predict(self, record, horizon=1):
        y, u, n = record.y.astype(float), record.u, self.max_lag_
        out = y.copy()
        a, b, c = self.theta_[: self.ny], self.theta_[self.ny : self.ny + self.nu], self.theta_[-1]
        if horizon == 1:
            X, _ = self._regressors(y, u)
            out[n:] = X @ self.theta_
        else:
            for k in range(n, len(y)):
                out[k] = (
                    sum(a[i] * out[k - 1 - i] for i in range(self.ny))
                    + sum(b[i] * u[k - 1 - i] for i in range(self.nu))
                    + c
                )
        if self.degrade:
            out[n:] = out[n:] + self.degrade * np.std(y)
        return out

    def _state(self):
        return {"theta_": self.theta_.tolist(), "max_lag_": self.max_lag_}

    def _load_state(self, state):
        self.theta_ = np.asarray(state["theta_"])
        self.max_lag_ = state["max_lag_"]
        self.n_parameters_ = self.theta_.size
