"""Linear ARX and ARMAX identifiers (dissertation §2.5–2.6, eq. 2-4/2-5, 2-16; registry ids ``arx``, ``armax``).

ARMAX (eq. 2-4), written in regression form::

    y(t) = Σ_{i=1}^{n_y} θ_{y,i} y(t−i) + Σ_{i=0}^{n_u−1} θ_{u,i} u(t−n_k−i) + Σ_{j=1}^{n_e} θ_{e,j} e(t−j) + e(t)

so that A(q) = 1 − Σ θ_{y,i} q^{−i}, B(q) = Σ θ_{u,i} q^{−i} (applied to u(t − n_k)), C(q) = 1 + Σ θ_{e,j} q^{−j}
(eq. 2-5). ARX is the case n_e = 0, estimated by linear least squares. ARMAX is estimated by

- ``method="pem"`` (default): the prediction-error method — numerical minimisation of Σ e(t, θ)² with
  e(t, θ) = [A(q) y(t) − B(q) u(t − n_k)] / C(q) (eq. 2-16), by scipy's Levenberg–Marquardt with the analytic
  Jacobian (each column a regressor filtered by 1/C), started from extended least squares;
- ``method="els"``: extended least squares — least squares on [y lags, u lags, e lags] with e the residuals of
  the previous iteration, repeated until the parameters settle.

Standard errors: σ̂² (JᵀJ)⁻¹ with σ̂² = SSR/(N − p) (J = regressor matrix for LS/ELS, Jacobian for PEM).
Both models predict through the compiled polynomial machinery (one-step, k-step, free run).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import least_squares as _scipy_lsq
from scipy.signal import lfilter

from sysid import frols as fr
from sysid.errors import ConfigError, DataError
from sysid.polynomial import PolynomialModel, check_records
from sysid.record import Record

__all__ = ["ARX", "ARMAX"]


class _LinearBase(PolynomialModel):
    """ARX/ARMAX share the term layout: all y lags, all u lags, (all e lags), optional constant."""

    def _linear_structure(self, records: list[Record], ne: int) -> fr.Structure:
        s = self._structure(records[0].n_outputs, records[0].n_inputs, ne, degree=1, constant=self.intercept)
        return s

    def polynomials(self, output: int = 0) -> dict[str, Any]:
        """A, B, C coefficient lists of eq. 2-5 for one output (B per input; MIMO: cross-output A terms listed)."""
        self._check_fitted()
        s = self.structure_
        a = np.zeros(self.ny + 1)
        a[0] = 1.0
        b = np.zeros((s.n_inputs, self.nu))
        c = np.zeros(getattr(self, "ne", 0) + 1)
        c[0] = 1.0
        se = {"a": np.zeros(self.ny + 1), "b": np.zeros((s.n_inputs, self.nu)), "c": np.zeros(len(c))}
        for term, th, sd in zip(self.terms_[output], self.theta_[output], self.stderr_[output]):
            if not term:
                continue
            kind, ch, lag = s.regressors[term[0]]
            if kind == "y" and ch == output:
                a[lag] = -th
                se["a"][lag] = sd
            elif kind == "u":
                b[ch, lag - self.nk] = th
                se["b"][ch, lag - self.nk] = sd
            elif kind == "e" and ch == output:
                c[lag] = th
                se["c"][lag] = sd
        return {"A": a, "B": b if s.n_inputs > 1 else b[0], "C": c,
                "A_stderr": se["a"], "B_stderr": se["b"] if s.n_inputs > 1 else se["b"][0], "C_stderr": se["c"]}


    def parameters(self) -> list[dict[str, Any]]:
        """``[{"name", "value", "std"}]`` in MATLAB's convention, so that the numbers compare with its ``arx``:
        A(q) = 1 + a1 q⁻¹ + …, B(q) = b1 q^-nk + b2 q^-(nk+1) + … (``b1_u2`` … for the 2nd input),
        C(q) = 1 + c1 q⁻¹ + …; one output."""
        self._check_fitted()
        if self.structure_.n_outputs != 1:
            return []
        p = self.polynomials(0)
        out = [{"name": f"a{k}", "value": float(p["A"][k]), "std": float(p["A_stderr"][k])}
               for k in range(1, len(p["A"]))]
        B = np.atleast_2d(p["B"])
        Bs = np.atleast_2d(p["B_stderr"])
        for i in range(B.shape[0]):
            suffix = f"_u{i + 1}" if B.shape[0] > 1 else ""
            out += [{"name": f"b{k + 1}{suffix}", "value": float(B[i, k]), "std": float(Bs[i, k])}
                    for k in range(B.shape[1])]
        out += [{"name": f"c{k}", "value": float(p["C"][k]), "std": float(p["C_stderr"][k])}
                for k in range(1, len(p["C"]))]
        return out

    def poles(self) -> list[dict[str, Any]]:
        """Roots of A(q) (one output; ``std`` is None: only the parameters' standard errors are kept)."""
        self._check_fitted()
        if self.structure_.n_outputs != 1:
            raise ConfigError(f"{self.name}: poles are listed for one output only")
        from sysid.uncertainty import poles_with_std

        return poles_with_std(self.polynomials(0)["A"], None)

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "terms_") and self.structure_.n_outputs == 1:
            d["parameters"] = self.parameters()
            d["poles"] = self.poles()
        if getattr(self, "chosen_orders_", None):
            d["chosen_orders"] = self.chosen_orders_
            d["order_selection"] = self.order_table_
        return d


class ARX(_LinearBase):
    """ARX by least squares: A(q) y(t) = B(q) u(t − n_k) + e(t).

    Parameters: ``ny`` (order of A), ``nu`` (order of B), ``nk`` (delay, samples), ``intercept`` (add a constant),
    ``orders`` (``"given"``: use ny, nu; ``"auto"``: choose ny = nu by hold-out free-run error over a grid up to
    ``max_order`` (:func:`sysid.order.select_arx_orders`), then ``ny``/``nu`` hold the chosen order and
    ``chosen_orders_`` / ``order_table_`` report it).
    MIMO: one model per output over the lags of every output and input.
    """

    name = "arx"

    def __init__(self, ny: int = 2, nu: int = 2, nk: int = 1, intercept: bool = False, orders: str = "given",
                 max_order: int = 100):
        self.ny = ny
        self.nu = nu
        self.nk = nk
        self.intercept = intercept
        self.orders = orders
        self.max_order = max_order

    def _fit_records(self, records: list[Record]) -> None:
        if self.orders not in ("given", "auto"):
            raise ConfigError(f"arx: orders must be 'given' or 'auto', got {self.orders!r}")
        self.chosen_orders_ = {}
        if self.orders == "auto":
            from sysid.order import select_arx_orders

            probe = ARX(nk=self.nk, intercept=self.intercept)
            n, self.order_table_ = select_arx_orders(records, self.nk, int(self.max_order), probe)
            self.ny = self.nu = n
            self.chosen_orders_ = {"ny": n, "nu": n}
        s = self._linear_structure(records, 0)
        check_records(records, s.max_lag, len(s.terms) + 1, self.name)
        self.structure_ = s
        self.terms_, self.theta_, self.stderr_, self.err_ = [], [], [], []
        for o in range(s.n_outputs):
            ls = fr.least_squares(records, s, s.terms, o)
            self.terms_.append(list(s.terms))
            self.theta_.append(ls.theta)
            self.stderr_.append(ls.stderr)
            self.err_.append([None] * len(s.terms))
        self.noise_variance_ = None


class ARMAX(_LinearBase):
    """ARMAX (eq. 2-4/2-5) by the prediction-error method (``method="pem"``) or extended least squares (``"els"``).

    Parameters: ``ny, nu, ne, nk`` orders and delay; ``intercept``; ``max_iter`` (ELS iterations, and the
    initialisation of PEM); ``tol`` (relative parameter change ending ELS).
    One output (several inputs allowed).
    """

    name = "armax"

    def __init__(self, ny: int = 2, nu: int = 2, ne: int = 2, nk: int = 1, method: str = "pem",
                 intercept: bool = False, max_iter: int = 50, tol: float = 1e-8):
        self.ny = ny
        self.nu = nu
        self.ne = ne
        self.nk = nk
        self.method = method
        self.intercept = intercept
        self.max_iter = max_iter
        self.tol = tol

    def _fit_records(self, records: list[Record]) -> None:
        if self.method not in ("pem", "els"):
            raise ConfigError(f"armax: method must be 'pem' or 'els', got {self.method!r}")
        if int(self.ne) < 1:
            raise ConfigError("armax: ne must be >= 1 (use arx without a noise model)")
        if records[0].n_outputs != 1:
            raise ConfigError(f"armax: one output supported, the data have {records[0].n_outputs}; "
                              "use arx or narmax-poly for several outputs")
        s = self._linear_structure(records, self.ne)
        check_records(records, s.max_lag, len(s.terms) + 1, self.name)
        self.structure_ = s
        theta, stderr, e_list, iters = self._els(records, s)
        self.els_iterations_ = iters
        # PEM: minimise; ELS: keep the ELS estimate but take its standard errors from the prediction-error
        # gradient (regressors filtered by 1/C) — plain LS errors ignore the estimated e and were ~1.6× too small.
        theta, stderr, self.pem_status_ = self._pem(records, s, theta, optimise=self.method == "pem")
        self.terms_ = [list(s.terms)]
        self.theta_ = [np.asarray(theta)]
        self.stderr_ = [np.asarray(stderr)]
        self.err_ = [[None] * len(s.terms)]

    # ---------------------------------------------------------------- ELS
    def _els(self, records, s):
        zeros = [np.zeros((len(r), 1)) for r in records]
        proc = [t for t in s.terms if not s.is_noise(t)]
        ls = fr.least_squares(records, s, proc, 0, e_list=zeros)
        e_list = fr.fitted_residuals(records, s, [proc], [ls.theta], e_list=zeros)
        theta_prev = None
        it = 0
        for it in range(1, int(self.max_iter) + 1):
            ls = fr.least_squares(records, s, s.terms, 0, e_list=e_list)
            e_list = fr.fitted_residuals(records, s, [s.terms], [ls.theta], e_list=e_list)
            # relative change per parameter, without an absolute floor (in SI units a parameter may be ~1e-12)
            if theta_prev is not None and np.max(np.abs(ls.theta - theta_prev) / np.maximum(
                    np.maximum(np.abs(ls.theta), np.abs(theta_prev)), 1e-300)) < self.tol:
                break
            theta_prev = ls.theta
        return ls.theta, ls.stderr, e_list, it

    # ---------------------------------------------------------------- PEM
    def _layout(self, s):
        """Indices of the y, u, e and constant terms in s.terms (degree-1 structure)."""
        idx = {"y": [], "u": [], "e": [], "c": []}
        for j, t in enumerate(s.terms):
            if not t:
                idx["c"].append(j)
            else:
                idx[s.regressors[t[0]][0]].append(j)
        return idx

    def _pem(self, records, s, theta0, optimise: bool = True):
        L = s.max_lag
        idx = self._layout(s)
        proc_idx = idx["y"] + idx["u"] + idx["c"]
        proc_terms = [s.terms[j] for j in proc_idx]
        # Regressor columns of the process part are fixed (measured data): build them once per record.
        zeros = [np.zeros((len(r), 1)) for r in records]
        blocks = []
        for rec, z in zip(records, zeros):
            X = np.vstack([x for x, _ in fr.lagged_chunks([rec], s, [z])]) if len(rec) > L else None
            P = fr.term_columns(X, proc_terms)
            yv = rec.y.reshape(-1)[L:]
            blocks.append((P, yv, len(rec)))
        ne = len(idx["e"])
        e_lags = [s.regressors[s.terms[j][0]][2] for j in idx["e"]]

        def split(theta):
            th_p = theta[: len(proc_idx)]
            c = np.zeros(max(e_lags) + 1)
            c[0] = 1.0
            for lg, v in zip(e_lags, theta[len(proc_idx):]):
                c[lg] = v
            return th_p, c

        def residual(theta):
            th_p, c = split(theta)
            out = []
            for P, yv, _ in blocks:
                v = yv - P @ th_p
                out.append(lfilter([1.0], c, v))
            return np.concatenate(out)

        def jac(theta):
            th_p, c = split(theta)
            cols = []
            for P, yv, _ in blocks:
                v = yv - P @ th_p
                e = lfilter([1.0], c, v)
                Jp = -lfilter([1.0], c, P, axis=0)
                Je = np.empty((len(e), ne))
                for k, lg in enumerate(e_lags):
                    el = np.zeros_like(e)
                    el[lg:] = e[:-lg]
                    Je[:, k] = -lfilter([1.0], c, el)
                cols.append(np.hstack([Jp, Je]))
            return np.vstack(cols)

        x0 = np.concatenate([np.asarray(theta0)[proc_idx], np.asarray(theta0)[idx["e"]]])
        if optimise and not np.all(np.abs(np.roots(split(x0)[1])) < 1.0):
            # ELS gave an unstable noise model: start PEM from C = 1 instead.
            x0[len(proc_idx):] = 0.0
        if optimise:
            sol = _scipy_lsq(residual, x0, jac=jac, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12,
                             max_nfev=200 * len(x0))
            x, r, J, message = sol.x, sol.fun, sol.jac, str(sol.message)
        else:
            x = np.concatenate([np.asarray(theta0)[proc_idx], np.asarray(theta0)[idx["e"]]])
            r, J, message = residual(x), jac(x), "extended least squares"
        n, p = r.size, x.size
        sigma2 = float(r @ r) / max(n - p, 1)
        try:
            cov = sigma2 * np.linalg.inv(J.T @ J)
            se = np.sqrt(np.maximum(np.diag(cov), 0.0))
        except np.linalg.LinAlgError:
            se = np.full(p, np.nan)
        theta = np.empty(len(s.terms))
        stderr = np.empty(len(s.terms))
        order = proc_idx + idx["e"]
        theta[order] = x
        stderr[order] = se
        if not np.all(np.abs(np.roots(split(x)[1])) < 1.0):
            raise DataError(f"armax ({self.method}): the fit gave a noise polynomial C with roots outside the "
                            "unit circle (non-invertible); try method=els or other orders")
        return theta, stderr, message

    def _extra_state(self) -> dict[str, Any]:
        return {}
