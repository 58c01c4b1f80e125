"""Polynomial NARX and NARMAX identifiers (dissertation §2.5–2.6, eq. 2-6 … 2-24; registry ids ``narx-poly``,
``narmax-poly``).

- **NARXPoly** (eq. 2-9): candidate terms of degree ≤ ``degree`` over y and u lags; FROLS selection
  (:mod:`sysid.frols`) by 1 − ΣERR < ``rho_p`` (``criterion="err"``) or by an information criterion
  (``"aic" | "bic" | "fpe" | "lilc"``, default ``"bic"``); final parameters by least squares.
- **NARMAXPoly** (eq. 2-6/2-7): ELS-FROLS, steps 1–4 of §2.6: (1) structure from n_u, n_y, n_e, n_l;
  (2) process terms by FROLS; (3) noise terms (any term containing an e lag) selected on the residuals by
  ERR ≥ ``rho_n`` (or the same information criterion), re-estimating the parameters and the residuals
  (extended least squares) until the terms and parameters settle; (4) final least squares.

MIMO: one model per output over shared regressors (the lags of every output and input); all outputs come from
the same pass over the data. A list of Records is several experiments: no regressor spans two of them.
Prediction (one-step, k-step at every sample, free run) is compiled (:mod:`sysid.simulate`).
"""

from __future__ import annotations

import warnings
from typing import Any, Sequence

import numpy as np

from sysid import frols as fr
from sysid import simulate as sim
from sysid.base import Identifier, as_record_list
from sysid.errors import ConfigError, DataError, DivergenceWarning
from sysid.record import Record

__all__ = ["PolynomialModel", "NARXPoly", "NARMAXPoly", "check_records"]

# A free run is declared diverged when it leaves ±DIVERGENCE_FACTOR × (largest |y| seen in estimation).
DIVERGENCE_FACTOR = 1e3


def check_records(records: Sequence[Record], max_lag: int, min_rows: int, what: str) -> None:
    """Refuse data that cannot be identified: NaN/inf, too few samples for the lags, constant input."""
    n_in, n_out = records[0].n_inputs, records[0].n_outputs
    rows = 0
    for rec in records:
        if rec.n_inputs != n_in or rec.n_outputs != n_out:
            raise DataError(f"{rec.source}: {rec.n_inputs} inputs / {rec.n_outputs} outputs, but the first record has "
                            f"{n_in} / {n_out}")
        for name, arr in (("u", rec.u), ("y", rec.y)):
            if not np.isfinite(arr).all():
                i = int(np.flatnonzero(~np.isfinite(arr.reshape(arr.shape[0], -1)).any(axis=1))[0])
                raise DataError(f"{rec.source}: {name} has non-finite (NaN/inf) samples, first at index {i}")
        if len(rec) <= max_lag:
            raise DataError(f"{rec.source}: {len(rec)} samples are too few for the lags of {what} "
                            f"(max lag {max_lag}; need more than {max_lag} samples per record)")
        rows += len(rec) - max_lag
    if rows < min_rows:
        raise DataError(f"{what}: {rows} usable samples (after the max lag {max_lag}) are too few for "
                        f"{min_rows - 1} candidate parameters; give more data or smaller lags/degree")
    u_all = np.concatenate([r.u.reshape(len(r), -1) for r in records])
    for ch in range(u_all.shape[1]):
        if np.ptp(u_all[:, ch]) == 0.0:
            name = "u" if u_all.shape[1] == 1 else f"u{ch + 1}"
            raise DataError(f"{records[0].source}: input {name} is constant ({u_all[0, ch]:g}); "
                            "a constant input does not excite the system, nothing to identify")
    y_all = np.concatenate([r.y.reshape(len(r), -1) for r in records])
    for ch in range(y_all.shape[1]):
        if np.ptp(y_all[:, ch]) == 0.0:
            name = "y" if y_all.shape[1] == 1 else f"y{ch + 1}"
            raise DataError(f"{records[0].source}: output {name} is constant ({y_all[0, ch]:g}); nothing to identify")


class PolynomialModel(Identifier):
    """Shared machinery of every model linear in its parameters over polynomial terms of lagged y, u, e.

    Subclasses implement ``_fit_records(records)`` setting ``structure_`` and per output ``terms_`` (list of
    term tuples), ``theta_``, ``stderr_``, ``err_``.
    """

    # -------------------------------------------------------------- common learned state
    def _structure(self, n_outputs: int, n_inputs: int, ne: int = 0, degree: int = 1, constant: bool = True) -> fr.Structure:
        regs = fr.make_regressors(self.ny, self.nu, ne, self.nk, n_outputs, n_inputs)
        if not regs:
            raise ConfigError(f"{self.name}: no regressors (ny = nu = 0)")
        return fr.Structure(regs, fr.candidate_terms(len(regs), degree, constant), n_outputs, n_inputs)

    def fit(self, data: Record | Sequence[Record]) -> "PolynomialModel":
        records = as_record_list(data)
        self._fit_records(records)
        y_max = max(float(np.max(np.abs(r.y))) for r in records)
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
        if getattr(self, "_compiled", None) is None:
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
            self._compiled = sim.CompiledModel(n_out, s.n_inputs, s.has_e, col, lag, terms,
                                               [len(t) for t in self.terms_], theta, s.max_lag,
                                               kinds=[k for k, _, _ in s.regressors])
        return self._compiled

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
            raise DataError(f"{record.source}: {record.n_inputs} inputs / {record.n_outputs} outputs, model was fitted "
                            f"on {self.n_inputs_} / {self.n_outputs_}")
        m = self.compiled()
        u = record.u.reshape(len(record), -1)
        y = record.y.reshape(len(record), -1)
        self.diverged_at_ = None
        if horizon is None:
            yhat, bad = sim.free_run(m, u, y, self.y_bound_)
        else:
            if isinstance(horizon, bool) or int(horizon) != horizon or horizon < 1:
                raise ConfigError(f"horizon must be a positive integer or None (free run), got {horizon!r}")
            if horizon == 1:
                yhat, _ = sim.one_step(m, u, y)
                bad = -1 if np.isfinite(yhat).all() else int(np.flatnonzero(~np.isfinite(yhat).any(axis=1))[0])
            else:
                yhat, bad = sim.k_step(m, u, y, int(horizon), self.y_bound_)
        if bad >= 0:
            self.diverged_at_ = int(bad)
            what = "free run" if horizon is None else f"{horizon}-step prediction"
            warnings.warn(f"{self.name}: {what} diverged at sample {bad} (beyond ±{self.y_bound_:.3g} or non-finite); "
                          "the remaining samples are nan", DivergenceWarning, stacklevel=2)
        return yhat.reshape(record.y.shape)

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
                row = {"term": fr.term_name(term, names_all, self.structure_.n_outputs, self.structure_.n_inputs),
                       "parameter": float(self.theta_[o][i]), "stderr": float(self.stderr_[o][i]),
                       "err": (None if self.err_[o][i] is None else float(self.err_[o][i]))}
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
            "n_outputs": s.n_outputs, "n_inputs": s.n_inputs,
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
        self.structure_ = fr.Structure(regs, sorted({t for ts in terms for t in ts}), int(state["n_outputs"]),
                                       int(state["n_inputs"]))
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


def _check_common(obj) -> None:
    if obj.criterion not in fr.CRITERIA:
        raise ConfigError(f"{obj.name}: criterion {obj.criterion!r} unknown; valid: {', '.join(fr.CRITERIA)}")
    if not (0.0 < float(obj.rho_p) < 1.0):
        raise ConfigError(f"{obj.name}: rho_p must lie in (0, 1), got {obj.rho_p}")
    if obj.max_terms is not None and int(obj.max_terms) < 1:
        raise ConfigError(f"{obj.name}: max_terms must be >= 1, got {obj.max_terms}")


class NARXPoly(PolynomialModel):
    """Polynomial NARX by FROLS (eq. 2-9, 2-17 … 2-24).

    Parameters
    ----------
    ny, nu : output and input lags (y(k−1)..y(k−ny), u(k−nk)..u(k−nk−nu+1)).
    nk : input delay in samples (1: u(k−1) is the most recent input regressor; 0 allows direct feed-through).
    degree : polynomial degree n_l.
    criterion : ``"err"`` (stop when 1 − ΣERR < rho_p, eq. 2-21) or ``"aic" | "bic" | "fpe" | "lilc"``
        (order selection in the same FROLS pass; BIC is the default because AIC over-fits at large N).
    rho_p : ERR tolerance for ``criterion="err"``.
    max_terms : most terms scored (and selected); None = all candidates.
    constant : include the constant term among the candidates.
    chunk : rows per chunk in the one-pass Gram accumulation (memory ≈ chunk × candidates × 8 B).
    """

    name = "narx-poly"

    def __init__(self, ny: int = 2, nu: int = 2, nk: int = 1, degree: int = 2, criterion: str = "bic",
                 rho_p: float = 1e-4, max_terms: int = 40, constant: bool = True, chunk: int = fr.DEFAULT_CHUNK):
        self.ny = ny
        self.nu = nu
        self.nk = nk
        self.degree = degree
        self.criterion = criterion
        self.rho_p = rho_p
        self.max_terms = max_terms
        self.constant = constant
        self.chunk = chunk

    def _fit_records(self, records: list[Record]) -> None:
        _check_common(self)
        s = self._structure(records[0].n_outputs, records[0].n_inputs, 0, self.degree, self.constant)
        check_records(records, s.max_lag, len(s.terms) + 1 if self.max_terms is None else min(len(s.terms), self.max_terms) + 1,
                      self.name)
        G, n = fr.gram_matrix(records, s, chunk=self.chunk)
        self.structure_ = s
        self.terms_, self.theta_, self.stderr_, self.err_ = [], [], [], []
        self.criterion_values_ = []
        for o in range(s.n_outputs):
            res = fr.frols(G, len(s.terms), o, n, self.criterion, self.rho_p, self.max_terms)
            terms = [s.terms[j] for j in res.selected]
            ls = fr.least_squares(records, s, terms, o, chunk=self.chunk)
            self.terms_.append(terms)
            self.theta_.append(ls.theta)
            self.stderr_.append(ls.stderr)
            self.err_.append(res.err)
            self.criterion_values_.append(res.criterion_values)


def _recursive_residuals_impl(model: PolynomialModel, records, s, terms_all, thetas) -> list[np.ndarray]:
    model.structure_, model.terms_, model.theta_ = s, terms_all, thetas
    model._compiled = None
    m = model.compiled()
    out = []
    for rec in records:
        _, e = sim.one_step(m, rec.u.reshape(len(rec), -1), rec.y.reshape(len(rec), -1))
        out.append(e)
    model._compiled = None
    return out


class NARMAXPoly(PolynomialModel):
    """Polynomial NARMAX by ELS-FROLS (§2.6 steps 1–4, eq. 2-6/2-7).

    Parameters as :class:`NARXPoly`, plus ``ne`` (noise lags e(k−1)..e(k−ne)), ``rho_n`` (a noise term is added
    while its ERR ≥ rho_n, when ``criterion="err"``; default 1e-5 = rho_p/10 as in the dissertation's Table 5.1;
    otherwise the information criterion decides), ``els_iter``
    (most extended-least-squares iterations) and ``els_tol`` (relative parameter change that ends them).
    """

    name = "narmax-poly"

    def __init__(self, ny: int = 2, nu: int = 2, ne: int = 2, nk: int = 1, degree: int = 2, criterion: str = "bic",
                 rho_p: float = 1e-4, rho_n: float = 1e-5, max_terms: int = 40, els_iter: int = 20,
                 els_tol: float = 1e-6, constant: bool = True, chunk: int = fr.DEFAULT_CHUNK):
        self.ny = ny
        self.nu = nu
        self.ne = ne
        self.nk = nk
        self.degree = degree
        self.criterion = criterion
        self.rho_p = rho_p
        self.rho_n = rho_n
        self.max_terms = max_terms
        self.els_iter = els_iter
        self.els_tol = els_tol
        self.constant = constant
        self.chunk = chunk

    def _recursive_residuals(self, records, s, terms_all, thetas) -> list[np.ndarray]:
        """One-step prediction errors of the current model, e computed recursively (pseudo-linear regression)."""
        return _recursive_residuals_impl(self, records, s, terms_all, thetas)

    def _fit_records(self, records: list[Record]) -> None:
        _check_common(self)
        if int(self.ne) < 1:
            raise ConfigError(f"{self.name}: ne must be >= 1 (use narx-poly for a model without noise terms)")
        s = self._structure(records[0].n_outputs, records[0].n_inputs, self.ne, self.degree, self.constant)
        process = [t for t in s.terms if not s.is_noise(t)]
        noise = [t for t in s.terms if s.is_noise(t)]
        n_min = min(len(process), self.max_terms or len(process)) + 1
        check_records(records, s.max_lag, n_min, self.name)
        n_out = s.n_outputs
        self.structure_ = s
        # Step 2: process terms by FROLS (noise regressors are not needed yet).
        zeros = [np.zeros((len(r), n_out)) for r in records]  # e regressors are unused by process terms
        G, n = fr.gram_matrix(records, s, terms=process, e_list=zeros, chunk=self.chunk)
        proc_sel, proc_err = [], []
        for o in range(n_out):
            res = fr.frols(G, len(process), o, n, self.criterion, self.rho_p, self.max_terms)
            proc_sel.append([process[j] for j in res.selected])
            proc_err.append(res.err)
        thetas = [fr.least_squares(records, s, proc_sel[o], o, e_list=zeros, chunk=self.chunk).theta
                  for o in range(n_out)]
        e_list = fr.fitted_residuals(records, s, proc_sel, thetas, e_list=zeros, chunk=self.chunk)
        # Step 3: noise terms on the residuals, extended least squares until terms and parameters settle.
        # With criterion="err" the process terms of step 2 stay and noise terms are added while ERR >= rho_n.
        # With an information criterion, process and noise terms are re-selected together on every iteration
        # (the coloured residuals of step 2 make the criterion accept spurious process terms that the noise
        # terms then explain).
        joint = self.criterion != "err"
        union_proc = process if joint else sorted({t for ts in proc_sel for t in ts})
        cand = union_proc + noise
        prev = None
        self.els_iterations_ = 0
        self.els_converged_ = False
        for it in range(int(self.els_iter)):
            G, n = fr.gram_matrix(records, s, terms=cand, e_list=e_list, chunk=self.chunk)
            terms_all, errs_all, lss = [], [], []
            for o in range(n_out):
                if joint:
                    res = fr.frols(G, len(cand), o, n, self.criterion, self.rho_p, self.max_terms)
                else:
                    forced = [cand.index(t) for t in proc_sel[o]]
                    allowed = np.array([False] * len(union_proc) + [True] * len(noise))
                    max_terms = len(forced) + (self.max_terms if self.max_terms is not None else len(noise))
                    res = fr.frols(G, len(cand), o, n, "err", self.rho_n, max_terms, forced=forced,
                                   allowed=allowed, continue_err=True)
                terms = [cand[j] for j in res.selected]
                ls = fr.least_squares(records, s, terms, o, e_list=e_list, chunk=self.chunk)
                terms_all.append(terms)
                errs_all.append(res.err)
                lss.append(ls)
            thetas = [ls.theta for ls in lss]
            new_e = self._recursive_residuals(records, s, terms_all, thetas)
            # The recursion e(t) = y(t) − ŷ(t|t−1) is unstable while the noise model is (e.g. an early estimate of an
            # MA coefficient above 1): then take the plain ELS residual y − Pθ with the previous e, which is bounded.
            plain = fr.fitted_residuals(records, s, terms_all, thetas, e_list=e_list, chunk=self.chunk)
            with np.errstate(over="ignore", invalid="ignore"):
                finite = all(np.isfinite(e).all() for e in new_e)
                if not finite or max(float(np.std(e)) for e in new_e) > 2.0 * max(float(np.std(e)) for e in plain):
                    new_e = plain
            self.els_iterations_ = it + 1
            cur = (terms_all, [ls.theta for ls in lss])
            done = False
            if prev is not None and prev[0] == terms_all:
                change = max(float(np.max(np.abs(a - b) / np.maximum(np.abs(a), 1e-12))) if a.size else 0.0
                             for a, b in zip(cur[1], prev[1]))
                done = change < self.els_tol
            prev = cur
            e_list = new_e
            if done:
                self.els_converged_ = True
                break
        # Step 4: final least squares on the residuals of the converged model.
        self.terms_, self.theta_, self.stderr_, self.err_ = [], [], [], []
        for o in range(n_out):
            ls = fr.least_squares(records, s, terms_all[o], o, e_list=e_list, chunk=self.chunk)
            self.terms_.append(terms_all[o])
            self.theta_.append(ls.theta)
            self.stderr_.append(ls.stderr)
            self.err_.append(errs_all[o])
        self.noise_terms_ = [[fr.term_name(t, s.regressors, s.n_outputs, s.n_inputs) for t in ts if s.is_noise(t)]
                             for ts in self.terms_]
