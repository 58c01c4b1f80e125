"""The polynomial model every identifier linear in its parameters extends (ARX/ARMAX, NARX/NARMAX; dissertation
§2.5–2.7): lagged y, u (and e) regressors, polynomial terms over them, and their compiled one-step, k-step and
free-run prediction (eq. 2-29, :mod:`sysid.polynomial.simulate`); saving and loading its terms and parameters.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from sysid.base import Identifier, as_record_list
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError, DivergenceWarning
from sysid.polynomial import frols as fr
from sysid.polynomial import simulate as sim

__all__ = ["PolynomialModel", "DIVERGENCE_FACTOR"]

#: what the products of two or more regressors are made of (option ``monomials_of``): lagged y and u (eq. 2-24), or
#: lagged y alone (the input enters linearly: a nonlinear feedback of the output, e.g. a restoring force)
MONOMIALS_OF = ("yu", "y")

# A free run is declared diverged when it leaves ±DIVERGENCE_FACTOR × (largest |y| seen in estimation).
DIVERGENCE_FACTOR = 1e3


class PolynomialModel(Identifier):
    """Shared machinery of every model linear in its parameters over polynomial terms of lagged y, u, e.

    Subclasses implement ``_fit_records(records)`` setting ``structure_`` and per output ``terms_`` (list of
    term tuples), ``theta_``, ``stderr_``, ``err_``.
    """

    _compiled: sim.CompiledModel | None

    # -------------------------------------------------------------- common learned state
    def _structure(
        self,
        n_outputs: int,
        n_inputs: int,
        ne: int = 0,
        degree: int = 1,
        constant: bool = True,
        monomials_of: str = "yu",
    ) -> fr.Structure:
        regs = fr.make_regressors(self.ny, self.nu, ne, self.nk, n_outputs, n_inputs)
        if not regs:
            raise ConfigError(f"{self.name}: no regressors (ny = nu = 0)")
        if monomials_of not in MONOMIALS_OF:
            raise ConfigError(f"{self.name}: monomials_of={monomials_of!r} not one of: {', '.join(MONOMIALS_OF)}")
        nonlinear = None if monomials_of == "yu" else [r for r, (kind, _, _) in enumerate(regs) if kind == "y"]
        terms = fr.candidate_terms(len(regs), degree, constant, nonlinear)
        return fr.Structure(regs, terms, n_outputs, n_inputs)

    def fit(self, data: Record | Sequence[Record]) -> PolynomialModel:
        records = as_record_list(data)
        self._fit_records(records)
        y_max = max(float(np.max(np.abs(r.output))) for r in records)
        self.y_bound_ = DIVERGENCE_FACTOR * max(y_max, 1e-300)
        self.n_outputs_ = records[0].n_outputs
        self.n_inputs_ = records[0].n_inputs
        self.max_lag_ = self.structure_.max_lag
        self.n_parameters_ = int(sum(len(t) for t in self.terms_))
        self._compiled = None
        self.diverged_at_ = None
        return self

    def _fit_records(self, records: list[Record]) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    # -------------------------------------------------------------- prediction
    def compiled(self) -> sim.CompiledModel:
        compiled = getattr(self, "_compiled", None)
        if compiled is None:
            s = self.structure_
            n_out = s.n_outputs
            t_max = max([len(t) for t in self.terms_] + [1])
            d_max = max([len(term) for ts in self.terms_ for term in ts] + [1])
            terms = -np.ones((n_out, t_max, d_max), dtype=np.int64)
            theta = np.zeros((n_out, t_max))
            for o in range(n_out):
                for i, term in enumerate(self.terms_[o]):
                    terms[o, i, : len(term)] = term
                    theta[o, i] = self.theta_[o][i]
            col = [s.column_of(r) for r in range(len(s.regressors))]
            lag = [lg for _, _, lg in s.regressors]
            compiled = self._compiled = sim.CompiledModel(
                n_out,
                s.n_inputs,
                s.has_e,
                col,
                lag,
                terms,
                [len(t) for t in self.terms_],
                theta,
                s.max_lag,
                kinds=[k for k, _, _ in s.regressors],
            )
        return compiled

    def _check_fitted(self) -> None:
        if not hasattr(self, "terms_"):
            raise ConfigError(f"{self.name}: model is not fitted (call fit first)")

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """One-step (``horizon=1``), k-step-ahead at every sample (``horizon=k``) or free run (``None``).

        The first ``max_lag_`` samples are copied from ``record.y``. A free run that diverges stops; the rest is
        nan, ``diverged_at_`` holds the sample index and a DivergenceWarning is issued.
        """
        self._check_fitted()
        record.require_output()
        if record.n_inputs != self.n_inputs_ or record.n_outputs != self.n_outputs_:
            raise DataError(
                f"{record.source}: {record.n_inputs} inputs / {record.n_outputs} outputs, model was fitted "
                f"on {self.n_inputs_} / {self.n_outputs_}"
            )
        m = self.compiled()
        u = record.u.reshape(len(record), -1)
        y = record.output.reshape(len(record), -1)
        self.diverged_at_ = None
        if horizon is None:
            yhat, bad = sim.free_run(m, u, y, self.y_bound_)
        else:
            if isinstance(horizon, bool) or int(horizon) != horizon or horizon < 1:
                raise ConfigError(f"horizon must be a positive integer or None (free run), got {horizon!r}")
            if horizon == 1:
                yhat, _ = sim.one_step(m, u, y)
                # a NARMAX residual recursion that leaves the bound (or overflows) is reported, not returned
                out = ~(np.abs(yhat) <= self.y_bound_).all(axis=1)
                bad = int(np.flatnonzero(out)[0]) if out.any() else -1
                if bad >= 0:
                    yhat[bad:] = np.nan
            else:
                yhat, bad = sim.k_step(m, u, y, int(horizon), self.y_bound_)
        if bad >= 0:
            self.diverged_at_ = int(bad)
            what = "free run" if horizon is None else f"{horizon}-step prediction"
            warnings.warn(
                f"{self.name}: {what} diverged at sample {bad} (beyond ±{self.y_bound_:.3g} or non-finite); "
                "the remaining samples are nan",
                DivergenceWarning,
                stacklevel=2,
            )
        return yhat.reshape(record.output.shape)

    def residuals(self, record: Record) -> np.ndarray:
        """One-step residuals e(t) = y(t) − ŷ(t|t−1) (eq. 2-16/2-30), zeros for the first max_lag_ samples."""
        e = record.y - self.predict(record, 1)
        return e

    # -------------------------------------------------------------- description / persistence
    def term_table(self) -> list[dict[str, Any]]:
        """Selected terms with parameter, standard error and ERR, per output (in order of selection)."""
        self._check_fitted()
        out = []
        names_all = self.structure_.regressors
        for o in range(len(self.terms_)):
            for i, term in enumerate(self.terms_[o]):
                row = {
                    "term": fr.term_name(term, names_all, self.structure_.n_outputs, self.structure_.n_inputs),
                    "parameter": float(self.theta_[o][i]),
                    "stderr": float(self.stderr_[o][i]),
                    "err": (None if self.err_[o][i] is None else float(self.err_[o][i])),
                }
                if self.structure_.n_outputs > 1:
                    row["output"] = o
                out.append(row)
        return out

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "terms_"):
            d["terms"] = self.term_table()
            d["max_lag"] = self.max_lag_
        return d

    def summary(self) -> str:
        """Human-readable table: term, parameter ± standard error, ERR."""
        lines = [f"{self.name}: {self.n_parameters_} terms"]
        for row in self.term_table():
            err = "" if row["err"] is None else f"  ERR {row['err']:.4e}"
            pre = f"[y{row['output'] + 1}] " if "output" in row else ""
            lines.append(f"  {pre}{row['term']:<28} {row['parameter']: .6g} ± {row['stderr']:.2g}{err}")
        return "\n".join(lines)

    def _state(self) -> dict[str, Any]:
        s = self.structure_
        return {
            "regressors": [list(r) for r in s.regressors],
            "n_outputs": s.n_outputs,
            "n_inputs": s.n_inputs,
            "terms": [[list(t) for t in ts] for ts in self.terms_],
            "theta": [np.asarray(t).tolist() for t in self.theta_],
            "stderr": [np.asarray(t).tolist() for t in self.stderr_],
            "err": [list(e) for e in self.err_],
            "y_bound": self.y_bound_,
            "extra": self._extra_state(),
        }

    def _extra_state(self) -> dict[str, Any]:
        return {}

    def _load_state(self, state: dict[str, Any]) -> None:
        regs = [(str(k), int(c), int(lg)) for k, c, lg in state["regressors"]]
        terms = [[tuple(int(i) for i in t) for t in ts] for ts in state["terms"]]
        self.structure_ = fr.Structure(
            regs, sorted({t for ts in terms for t in ts}), int(state["n_outputs"]), int(state["n_inputs"])
        )
        self.terms_ = terms
        self.theta_ = [np.asarray(t, dtype=float) for t in state["theta"]]
        self.stderr_ = [np.asarray(t, dtype=float) for t in state["stderr"]]
        self.err_ = [list(e) for e in state["err"]]
        self.y_bound_ = float(state["y_bound"])
        self.n_outputs_ = self.structure_.n_outputs
        self.n_inputs_ = self.structure_.n_inputs
        self.max_lag_ = self.structure_.max_lag
        self.n_parameters_ = int(sum(len(t) for t in terms))
        self._compiled = None
        self.diverged_at_ = None
        self._load_extra(state.get("extra", {}))

    def _load_extra(self, extra: dict[str, Any]) -> None:
        pass
