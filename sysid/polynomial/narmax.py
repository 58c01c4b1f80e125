"""Polynomial NARX and NARMAX identifiers (dissertation §2.5–2.6, eq. 2-6 … 2-24; registry ids ``narx-poly``,
``narmax-poly``).

- **NARXPoly** (eq. 2-9): candidate terms of degree ≤ ``degree`` over y and u lags; FROLS selection
  (:mod:`sysid.polynomial.frols`) by 1 − ΣERR < ``rho_p`` (``criterion="err"``) or by an information criterion
  (``"aic" | "bic" | "fpe" | "lilc"``, default ``"bic"``); final parameters by least squares.
- **NARMAXPoly** (eq. 2-6/2-7): ELS-FROLS, steps 1–4 of §2.6: (1) structure from n_u, n_y, n_e, n_l;
  (2) process terms by FROLS; (3) noise terms (any term containing an e lag) selected on the residuals by
  ERR ≥ ``rho_n`` (or the same information criterion), re-estimating the parameters and the residuals
  (extended least squares) until the terms and parameters settle; (4) final least squares. The returned noise
  model's residual recursion e(k) = y(k) − ŷ(k|k−1) (what one-step and k-step prediction run) is checked on the
  estimation data: bounded, and recovering from output kicks; noise terms that make it diverge are removed (e², e³
  terms first) and named in ``els_status_`` with a warning — never NaN parameters or a NaN one-step prediction
  on the estimation data.

MIMO: one model per output over shared regressors (the lags of every output and input); all outputs come from
the same pass over the data. A list of Records is several experiments: no regressor spans two of them.
Prediction (one-step, k-step at every sample, free run) is compiled (:mod:`sysid.polynomial.simulate`).
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from sysid.base import check_records
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.polynomial import frols as fr
from sysid.polynomial import simulate as sim
from sysid.polynomial.model import DIVERGENCE_FACTOR, PolynomialModel

__all__ = ["NARXPoly", "NARMAXPoly", "PolynomialModel", "DIVERGENCE_FACTOR", "check_records"]

# The residual recursion of a NARMAX noise model counts as unstable when it leaves ± this factor × the largest
# fitted (non-recursive) residual on the estimation data.
RECURSION_GROWTH = 10.0
# Robustness check of the returned noise model: KICKS output disturbances of KICK_SIZE × the largest fitted residual.
KICKS = 8
KICK_SIZE = 3.0


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
    monomials_of : ``"yu"``: candidate products of lagged y and u (eq. 2-24); ``"y"``: products of lagged y alone,
        the input entering linearly (a nonlinear feedback of the output, such as a Duffing oscillator's restoring
        force of its displacement: fewer candidates, and no powers of the input to grow beyond its estimation range).
    """

    name = "narx-poly"

    def __init__(
        self,
        ny: int = 2,
        nu: int = 2,
        nk: int = 1,
        degree: int = 2,
        criterion: str = "bic",
        rho_p: float = 1e-4,
        max_terms: int = 40,
        constant: bool = True,
        chunk: int = fr.DEFAULT_CHUNK,
        monomials_of: str = "yu",
    ):
        self.ny = ny
        self.nu = nu
        self.nk = nk
        self.degree = degree
        self.criterion = criterion
        self.rho_p = rho_p
        self.max_terms = max_terms
        self.constant = constant
        self.chunk = chunk
        self.monomials_of = monomials_of

    def _fit_records(self, records: list[Record]) -> None:
        _check_common(self)
        s = self._structure(records[0].n_outputs, records[0].n_inputs, 0, self.degree, self.constant, self.monomials_of)
        check_records(
            records,
            s.max_lag,
            len(s.terms) + 1 if self.max_terms is None else min(len(s.terms), self.max_terms) + 1,
            self.name,
        )
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
        _, e = sim.one_step(m, rec.u.reshape(len(rec), -1), rec.output.reshape(len(rec), -1))
        if e is None:  # a model with e terms (NARMAX) always returns its residuals
            raise RuntimeError("one-step prediction of a NARMAX model returned no residuals")
        out.append(e)
    model._compiled = None
    return out


class NARMAXPoly(PolynomialModel):
    """Polynomial NARMAX by ELS-FROLS (§2.6 steps 1–4, eq. 2-6/2-7).

    Parameters as :class:`NARXPoly`, plus ``ne`` (noise lags e(k−1)..e(k−ne)), ``rho_n`` (a noise term is added
    while its ERR ≥ rho_n, when ``criterion="err"``; default 1e-5 = rho_p/10 as in the dissertation's Table 5.1;
    otherwise the information criterion decides), ``els_iter``
    (most extended-least-squares iterations) and ``els_tol`` (relative parameter change that ends them).

    After fit: ``els_iterations_``, ``els_converged_``, ``els_unstable_`` (iterations whose noise model had a
    diverging residual recursion; ELS continued from the plain residual there), ``els_removed_terms_`` (noise terms
    removed from the final model to keep its recursion bounded) and ``els_status_`` (one line saying all that).
    """

    name = "narmax-poly"

    def __init__(
        self,
        ny: int = 2,
        nu: int = 2,
        ne: int = 2,
        nk: int = 1,
        degree: int = 2,
        criterion: str = "bic",
        rho_p: float = 1e-4,
        rho_n: float = 1e-5,
        max_terms: int = 40,
        els_iter: int = 20,
        els_tol: float = 1e-6,
        constant: bool = True,
        chunk: int = fr.DEFAULT_CHUNK,
    ):
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

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "els_status_"):
            d["els"] = {
                "iterations": self.els_iterations_,
                "converged": self.els_converged_,
                "unstable_iterations": list(self.els_unstable_),
                "removed_terms": list(self.els_removed_terms_),
                "status": self.els_status_,
            }
        return d

    def _recursion_bounded(self, records, s, terms_all, thetas, e_list, kicks: bool = False):
        """Recursive residuals of the model and whether they stay bounded on the estimation data: finite and
        within RECURSION_GROWTH × the largest fitted residual y − Pθ (computed with the ELS residuals e_list).
        A stable noise model keeps the two of the same size; an unstable one grows without bound.

        ``kicks``: also require the recursion to recover from KICKS disturbances of KICK_SIZE × the largest
        fitted residual spread over each record (y disturbed at one sample each, alternating sign). Terms of
        degree ≥ 2 in e make the recursion stable only near e = 0; a model that passes on the estimation data but
        leaves that region on other data (measured: Cascaded Tanks test record) fails this check."""
        new_e = self._recursive_residuals(records, s, terms_all, thetas)
        plain = fr.fitted_residuals(records, s, terms_all, thetas, e_list=e_list, chunk=self.chunk)
        with np.errstate(over="ignore", invalid="ignore"):
            ok = all(np.isfinite(e).all() for e in new_e)
            big = max(float(np.max(np.abs(p), initial=0.0)) for p in plain)
            lim = RECURSION_GROWTH * big
            if ok:
                ok = max(float(np.max(np.abs(e), initial=0.0)) for e in new_e) <= lim
            if ok and kicks and any(s.is_noise(t) for ts in terms_all for t in ts):
                kicked = []
                for rec in records:
                    y = np.array(rec.y, dtype=float, copy=True).reshape(len(rec), -1)
                    L = s.max_lag
                    at = np.linspace(L, len(rec) - 1, KICKS + 2).astype(int)[1:-1]
                    y[at] += KICK_SIZE * big * np.where(np.arange(at.size) % 2 == 0, 1.0, -1.0)[:, None]
                    kicked.append(Record(rec.u, y.reshape(rec.y.shape), fs=rec.fs))
                ek = self._recursive_residuals(kicked, s, terms_all, thetas)
                ok = (
                    all(np.isfinite(e).all() for e in ek)
                    and max(float(np.max(np.abs(e), initial=0.0)) for e in ek) <= lim
                )
        self._last_plain = plain
        return new_e, ok

    def _stable_noise_model(self, records, s, terms_all, lss, errs_all, e_list):
        """Remove noise terms until the residual recursion is bounded (§2.7: one-step prediction needs it).

        Order: first every term of degree ≥ 2 in e (e², e·e: a polynomial map of e, unbounded once e grows),
        then the last-selected noise term (smallest ERR) of each output, one at a time. The process parameters are
        kept as estimated (so the free run is unchanged); the remaining noise parameters are re-estimated on what
        the process part leaves.
        Returns (terms, lss, errs, names of the removed terms)."""
        new_e, ok = self._recursion_bounded(records, s, terms_all, [ls.theta for ls in lss], e_list, kicks=True)
        removed: list[str] = []
        first = True
        terms_all, errs_all, lss = [list(t) for t in terms_all], [list(e) for e in errs_all], list(lss)
        while not ok:
            changed = False
            for o, terms in enumerate(terms_all):
                e_deg = [sum(1 for r in t if s.regressors[r][0] == "e") for t in terms]
                if first and any(d >= 2 for d in e_deg):
                    drop = [i for i, d in enumerate(e_deg) if d >= 2]
                else:
                    drop = [i for i, d in enumerate(e_deg) if d > 0][-1:]
                if not drop:
                    continue
                changed = True
                pre = f"[y{o + 1}] " if s.n_outputs > 1 else ""
                removed += [pre + fr.term_name(terms[i], s.regressors, s.n_outputs, s.n_inputs) for i in drop]
                keep = [i for i in range(len(terms)) if i not in drop]
                terms_all[o] = [terms[i] for i in keep]
                errs_all[o] = [errs_all[o][i] for i in keep]
                lss[o] = self._refit_noise(records, s, terms_all[o], lss[o].theta[keep], lss[o].stderr[keep], o, e_list)
            first = False
            if not changed:
                raise DataError(
                    f"{self.name}: the one-step recursion of the process-only model is not finite "
                    "(non-finite parameters or regressors)"
                )
            new_e, ok = self._recursion_bounded(records, s, terms_all, [ls.theta for ls in lss], e_list, kicks=True)
        return terms_all, lss, errs_all, removed

    def _refit_noise(self, records, s, terms, theta, stderr, o, e_list) -> fr.LSResult:
        """Least squares of the noise-term parameters alone, the process parameters fixed: the remaining noise
        terms fit what the process part leaves (y − P_proc θ_proc) once some noise terms are removed."""
        theta = np.array(theta, dtype=float, copy=True)
        stderr = np.array(stderr, dtype=float, copy=True)
        nz = [i for i, t in enumerate(terms) if s.is_noise(t)]
        if not nz:
            return fr.LSResult(theta=theta, stderr=stderr, ssr=math.nan, n_samples=0)
        pr = [i for i in range(len(terms)) if i not in nz]
        rows_P, rows_r = [], []
        for X, Y in fr.lagged_chunks(records, s, e_list, self.chunk):
            P = fr.term_columns(X, terms)
            rows_P.append(P[:, nz])
            rows_r.append(Y[:, o] - P[:, pr] @ theta[pr])
        P, r = np.vstack(rows_P), np.concatenate(rows_r)
        sol, *_ = np.linalg.lstsq(P, r, rcond=None)
        if np.isfinite(sol).all():
            theta[nz] = sol
            res = r - P @ sol
            sigma2 = float(res @ res) / max(len(r) - len(nz), 1)
            try:
                stderr[nz] = np.sqrt(np.maximum(np.diag(sigma2 * np.linalg.inv(P.T @ P)), 0.0))
            except np.linalg.LinAlgError:  # pragma: no cover - dependent noise columns
                pass
        return fr.LSResult(theta=theta, stderr=stderr, ssr=math.nan, n_samples=len(r))

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
        thetas = [
            fr.least_squares(records, s, proc_sel[o], o, e_list=zeros, chunk=self.chunk).theta for o in range(n_out)
        ]
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
        self.els_unstable_ = []
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
                    res = fr.frols(
                        G,
                        len(cand),
                        o,
                        n,
                        "err",
                        self.rho_n,
                        max_terms,
                        forced=forced,
                        allowed=allowed,
                        continue_err=True,
                    )
                terms = [cand[j] for j in res.selected]
                ls = fr.least_squares(records, s, terms, o, e_list=e_list, chunk=self.chunk)
                terms_all.append(terms)
                errs_all.append(res.err)
                lss.append(ls)
            thetas = [ls.theta for ls in lss]
            # The pseudo-linear regression's next e is the recursion e(t) = y(t) − ŷ(t|t−1) of this model. While
            # that recursion is unstable (an early noise model with an MA root outside the unit circle, or e²/e³
            # terms that blow up once e grows) it is replaced by the plain residual y − Pθ computed with the
            # previous e, which is bounded; the iteration is recorded in els_unstable_.
            new_e, bounded = self._recursion_bounded(records, s, terms_all, thetas, e_list)
            plain = self._last_plain  # y − Pθ with the previous e, computed by the check
            if not bounded:
                self.els_unstable_.append(it + 1)
                new_e = plain
            elif max(float(np.std(e)) for e in new_e) > 2.0 * max(float(np.std(e)) for e in plain):
                new_e = plain
            self.els_iterations_ = it + 1
            cur = (terms_all, thetas)
            done = False
            if prev is not None and prev[0] == terms_all:
                # relative change per parameter, scale-invariant (no absolute floor: in SI units a parameter can
                # be ~1e-12 and still matter)
                change = max(
                    (
                        float(np.max(np.abs(a - b) / np.maximum(np.maximum(np.abs(a), np.abs(b)), 1e-300)))
                        if a.size
                        else 0.0
                    )
                    for a, b in zip(cur[1], prev[1])
                )
                done = change < self.els_tol
            prev = cur
            e_list = new_e
            if done:
                self.els_converged_ = True
                break
        # Step 4: final least squares on the residuals of the last iteration.
        terms_all = terms_all if int(self.els_iter) > 0 else [list(t) for t in proc_sel]
        errs_all = errs_all if int(self.els_iter) > 0 else proc_err
        lss = [fr.least_squares(records, s, terms_all[o], o, e_list=e_list, chunk=self.chunk) for o in range(n_out)]
        # The returned model must predict one step ahead: its residual recursion has to stay bounded on the
        # estimation data. If it does not, noise terms are removed until it does (the process part, hence the free
        # run, stays exactly the ELS estimate), and the reason is reported.
        terms_all, lss, errs_all, removed = self._stable_noise_model(records, s, terms_all, lss, errs_all, e_list)
        what = (
            "converged"
            if self.els_converged_
            else f"stopped after els_iter={self.els_iterations_} iterations "
            f"(relative parameter change not yet below els_tol={self.els_tol:g})"
        )
        if self.els_unstable_:
            what += (
                f"; the noise models of iterations {self.els_unstable_} had an unstable residual recursion "
                "(ELS continued from the plain residual)"
            )
        if removed:
            what += (
                f"; the final noise model's residual recursion diverged on the estimation data: removed "
                f"{', '.join(removed)} (process parameters unchanged, the remaining noise parameters re-estimated)"
            )
        self.els_status_ = what
        self.els_removed_terms_ = removed
        del self._last_plain
        if removed:
            warnings.warn(f"{self.name}: ELS {what}", UserWarning, stacklevel=3)
        self.terms_, self.theta_, self.stderr_, self.err_ = [], [], [], []
        for o in range(n_out):
            self.terms_.append(terms_all[o])
            self.theta_.append(lss[o].theta)
            self.stderr_.append(lss[o].stderr)
            self.err_.append(errs_all[o])
        self.noise_terms_ = [
            [fr.term_name(t, s.regressors, s.n_outputs, s.n_inputs) for t in ts if s.is_noise(t)] for ts in self.terms_
        ]
