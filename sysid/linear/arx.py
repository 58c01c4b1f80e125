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

Several outputs (ARMAX): y_o(t) = Σ_p Σ_i θ_{o,p,i} y_p(t−i) + Σ_j Σ_i θ_{o,j,i} u_j(t−n_k−i) + C_o(q) e_o(t), i.e.
the polynomial-matrix form A(q) y = B(q) u + C(q) e with A, B full and C diagonal.

Standard errors: σ̂² (JᵀJ)⁻¹ with σ̂² = SSR/(N − p) (J = regressor matrix for LS/ELS, Jacobian for PEM).
Both models predict through the compiled polynomial machinery (one-step, k-step, free run).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import least_squares as _scipy_lsq
from scipy.signal import lfilter

from sysid.base import check_records
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.polynomial import frols as fr
from sysid.polynomial.model import PolynomialModel

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
        return {
            "A": a,
            "B": b if s.n_inputs > 1 else b[0],
            "C": c,
            "A_stderr": se["a"],
            "B_stderr": se["b"] if s.n_inputs > 1 else se["b"][0],
            "C_stderr": se["c"],
        }

    def parameters(self) -> list[dict[str, Any]]:
        """``[{"name", "value", "std"}]`` in MATLAB's convention, so that the numbers compare with its ``arx``:
        A(q) = 1 + a1 q⁻¹ + …, B(q) = b1 q^-nk + b2 q^-(nk+1) + … (``b1_u2`` … for the 2nd input),
        C(q) = 1 + c1 q⁻¹ + …; one output."""
        self._check_fitted()
        if self.structure_.n_outputs != 1:
            return []
        p = self.polynomials(0)
        out = [
            {"name": f"a{k}", "value": float(p["A"][k]), "std": float(p["A_stderr"][k])} for k in range(1, len(p["A"]))
        ]
        B = np.atleast_2d(p["B"])
        Bs = np.atleast_2d(p["B_stderr"])
        for i in range(B.shape[0]):
            suffix = f"_u{i + 1}" if B.shape[0] > 1 else ""
            out += [
                {"name": f"b{k + 1}{suffix}", "value": float(B[i, k]), "std": float(Bs[i, k])}
                for k in range(B.shape[1])
            ]
        out += [
            {"name": f"c{k}", "value": float(p["C"][k]), "std": float(p["C_stderr"][k])} for k in range(1, len(p["C"]))
        ]
        return out

    def poles(self) -> list[dict[str, Any]]:
        """Roots of A(q) (one output; ``std`` is None: only the parameters' standard errors are kept)."""
        self._check_fitted()
        if self.structure_.n_outputs != 1:
            raise ConfigError(f"{self.name}: poles are listed for one output only")
        from sysid.linear.uncertainty import poles_with_std

        return poles_with_std(self.polynomials(0)["A"], None)

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "terms_") and self.structure_.n_outputs == 1:
            d["parameters"] = self.parameters()
            d["poles"] = self.poles()
        if getattr(self, "chosen_orders_", None):
            d["chosen_orders"] = self.chosen_orders_
            d["order_selection"] = getattr(self, "order_table_", None)
            d["order_search"] = getattr(self, "order_search_", None)
        return d


class ARX(_LinearBase):
    """ARX by least squares: A(q) y(t) = B(q) u(t − n_k) + e(t).

    Parameters: ``ny`` (order of A), ``nu`` (order of B), ``nk`` (delay, samples), ``intercept`` (add a constant),
    ``orders``: ``None`` (default) chooses the orders when neither ``ny`` nor ``nu`` is given and otherwise uses
    them (one left out is 2, the order this identifier always had); ``"auto"`` always chooses; ``"given"`` never
    does (ny, nu default 2). Choosing takes ny = nu by hold-out free-run error over a grid up to ``max_order``
    (:func:`sysid.linear.order.select_arx_orders`); the fitted model holds the chosen order in ``ny``/``nu`` and reports
    it in ``chosen_orders_`` / ``order_table_``.
    MIMO: one model per output over the lags of every output and input.
    """

    name = "arx"

    def __init__(
        self,
        ny: Any = None,
        nu: Any = None,
        nk: int = 1,
        intercept: bool = False,
        orders: Any = None,
        max_order: int = 100,
    ):
        self.ny = ny
        self.nu = nu
        self.nk = nk
        self.intercept = intercept
        self.orders = orders
        self.max_order = max_order

    def _fit_records(self, records: list[Record]) -> None:
        self.chosen_orders_ = {}
        if _choose_orders(self, ("ny", "nu")):
            n = _search_arx_order(self, records)
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

    def _extra_state(self) -> dict[str, Any]:
        return {"chosen_orders": dict(self.chosen_orders_)} if getattr(self, "chosen_orders_", None) else {}

    def _load_extra(self, extra: dict[str, Any]) -> None:
        self.chosen_orders_ = dict(extra.get("chosen_orders", {}))


def _search_arx_order(model, records: list[Record]) -> int:
    """ny = nu chosen by hold-out free-run error of ARX over the grid up to ``model.max_order`` (the table in
    ``model.order_table_``); the data's own faults (constant input, too few samples) are reported first, by name."""
    from sysid.linear.order import select_arx_orders

    check_records(records, max(1, int(model.nk)), 3, model.name)
    probe = ARX(nk=model.nk, intercept=model.intercept, orders="given")
    n, model.order_table_, model.order_search_ = select_arx_orders(records, model.nk, int(model.max_order), probe)
    return n


def _choose_orders(model, keys: tuple[str, ...]) -> bool:
    """Whether this fit chooses the orders ``keys`` (``orders`` option, see :class:`ARX`); fills the ones left out
    with the old default 2 when it does not. A model that chose once chooses again when refitted."""
    mode = model.orders
    if mode not in (None, "given", "auto"):
        raise ConfigError(f"{model.name}: orders must be 'given' or 'auto' (or left out), got {mode!r}")
    given = [k for k in keys if getattr(model, k) is not None]
    choose = mode == "auto" or (mode is None and (not given or getattr(model, "_orders_open", False)))
    model._orders_open = bool(choose and mode is None)
    for k in keys:
        v = getattr(model, k)
        if v is None:
            if not choose:
                setattr(model, k, 2)
        elif isinstance(v, (float, np.floating)) and float(v).is_integer():
            setattr(model, k, int(v))  # `--set ny=4` reads a number as float when the option's default is None
        elif isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise ConfigError(f"{model.name}: {k}: expected int, got {v!r}")
    return choose


#: restarts of the ARMAX prediction-error fit from C with its roots reflected inside the unit circle
PEM_REFLECTIONS = 3


def _invertible(c: np.ndarray) -> bool:
    """True when the monic polynomial ``c`` (coefficients of q⁰, q⁻¹, …) has every root inside the unit circle."""
    return bool(np.all(np.abs(np.roots(c)) < 1.0)) if len(c) > 1 else True


def reflect_inside(c: np.ndarray) -> np.ndarray:
    """The monic polynomial with the roots of ``c`` outside the unit circle replaced by 1/conj(root).

    |C'(e^{jω})| = |C(e^{jω})| / Π|r_i| over the reflected roots r_i, so C' gives the same noise spectrum shape
    (Ljung 1999, §10.1 and Söderström & Stoica 1989, §6.4: the spectral factor chosen minimum phase); roots on the
    circle move to radius 0.99."""
    r = np.roots(np.asarray(c, dtype=float))
    mag = np.abs(r)
    r = np.where(mag > 1.0, r / np.maximum(mag, 1e-300) ** 2, r)
    r = np.where(np.isclose(np.abs(r), 1.0), 0.99 * r, r)
    out = np.zeros(len(c))
    p = np.real(np.poly(r)) if len(r) else np.ones(1)
    out[: len(p)] = p
    return out


class ARMAX(_LinearBase):
    """ARMAX (eq. 2-4/2-5) by the prediction-error method (``method="pem"``) or extended least squares (``"els"``).

    Parameters: ``ny, nu, ne, nk`` orders and delay; ``intercept``; ``max_iter`` (ELS iterations, and the
    initialisation of PEM); ``tol`` (relative parameter change ending ELS); ``orders`` and ``max_order`` as for
    :class:`ARX`: with none of ny, nu, ne given, ny = nu are the ARX order chosen by hold-out free-run error and
    ne = 2 (reported in ``chosen_orders_``); otherwise an order left out is 2.
    Several outputs: one MISO ARMAX per output — the lags of every output and input, and the output's own noise
    lags (C diagonal) — estimated jointly by ELS (each output's residuals feed its own noise regressors) and
    refined output by output by PEM.
    """

    name = "armax"

    def __init__(
        self,
        ny: Any = None,
        nu: Any = None,
        ne: Any = None,
        nk: int = 1,
        method: str = "pem",
        intercept: bool = False,
        max_iter: int = 50,
        tol: float = 1e-8,
        orders: Any = None,
        max_order: int = 100,
    ):
        self.ny = ny
        self.nu = nu
        self.ne = ne
        self.nk = nk
        self.method = method
        self.intercept = intercept
        self.max_iter = max_iter
        self.tol = tol
        self.orders = orders
        self.max_order = max_order

    def _fit_records(self, records: list[Record]) -> None:
        if self.method not in ("pem", "els"):
            raise ConfigError(f"armax: method must be 'pem' or 'els', got {self.method!r}")
        self.chosen_orders_ = {}
        if _choose_orders(self, ("ny", "nu", "ne")):
            n = _search_arx_order(self, records)
            self.ny = self.nu = n
            self.ne = 2
            self.chosen_orders_ = {"ny": n, "nu": n, "ne": 2}
        if int(self.ne) < 1:
            raise ConfigError("armax: ne must be >= 1 (use arx without a noise model)")
        s = self._linear_structure(records, self.ne)
        # Several outputs: one MISO ARMAX per output over the lags of every output and input and the output's own
        # noise lags (diagonal C), so that each output's prediction error is filtered by its own C only.
        terms = [[t for t in s.terms if not s.is_noise(t) or s.regressors[t[0]][1] == o] for o in range(s.n_outputs)]
        check_records(records, s.max_lag, len(terms[0]) + 1, self.name)
        self.structure_ = s
        thetas, e_list, iters = self._els(records, s, terms)
        self.els_iterations_ = iters
        # PEM: minimise; ELS: keep the ELS estimate but take its standard errors from the prediction-error
        # gradient (regressors filtered by 1/C) — plain LS errors ignore the estimated e and were ~1.6× too small.
        fits = [
            self._pem(records, s, terms[o], o, thetas[o], optimise=self.method == "pem") for o in range(s.n_outputs)
        ]
        self.pem_status_ = fits[0][2] if len(fits) == 1 else [f[2] for f in fits]
        self.terms_ = terms
        self.theta_ = [np.asarray(f[0]) for f in fits]
        self.stderr_ = [np.asarray(f[1]) for f in fits]
        self.err_ = [[None] * len(t) for t in terms]

    # ---------------------------------------------------------------- ELS
    def _els(self, records, s, terms):
        n_out = s.n_outputs
        zeros = [np.zeros((len(r), n_out)) for r in records]
        proc = [t for t in s.terms if not s.is_noise(t)]
        th = [fr.least_squares(records, s, proc, o, e_list=zeros).theta for o in range(n_out)]
        e_list = fr.fitted_residuals(records, s, [proc] * n_out, th, e_list=zeros)
        theta_prev = None
        it = 0
        for it in range(1, int(self.max_iter) + 1):  # noqa: B007 (the count is returned)
            th = [fr.least_squares(records, s, terms[o], o, e_list=e_list).theta for o in range(n_out)]
            e_list = fr.fitted_residuals(records, s, terms, th, e_list=e_list)
            theta = np.concatenate(th)
            # relative change per parameter, without an absolute floor (in SI units a parameter may be ~1e-12)
            if (
                theta_prev is not None
                and np.max(
                    np.abs(theta - theta_prev) / np.maximum(np.maximum(np.abs(theta), np.abs(theta_prev)), 1e-300)
                )
                < self.tol
            ):
                break
            theta_prev = theta
        return th, e_list, it

    # ---------------------------------------------------------------- PEM
    def _layout(self, s, terms):
        """Indices of the y, u, e and constant terms in ``terms`` (degree-1 structure)."""
        idx: dict[str, list[int]] = {"y": [], "u": [], "e": [], "c": []}
        for j, t in enumerate(terms):
            if not t:
                idx["c"].append(j)
            else:
                idx[s.regressors[t[0]][0]].append(j)
        return idx

    def _pem(self, records, s, terms, output, theta0, optimise: bool = True):
        """Prediction-error fit of one output's parameters (``terms``), started from ``theta0``."""
        L = s.max_lag
        idx = self._layout(s, terms)
        proc_idx = idx["y"] + idx["u"] + idx["c"]
        proc_terms = [terms[j] for j in proc_idx]
        # Regressor columns of the process part are fixed (measured data): build them once per record.
        zeros = [np.zeros((len(r), s.n_outputs)) for r in records]
        blocks = []
        for rec, z in zip(records, zeros):
            if len(rec) <= L:  # check_records refuses such a record before any fit
                raise DataError(f"{rec.source}: {len(rec)} samples, not more than the largest lag {L}")
            X = np.vstack([x for x, _ in fr.lagged_chunks([rec], s, [z])])
            P = fr.term_columns(X, proc_terms)
            yv = rec.y.reshape(len(rec), -1)[L:, output]
            blocks.append((P, yv, len(rec)))
        ne = len(idx["e"])
        e_lags = [s.regressors[terms[j][0]][2] for j in idx["e"]]

        def split(theta):
            th_p = theta[: len(proc_idx)]
            c = np.zeros(max(e_lags) + 1)
            c[0] = 1.0
            for lg, v in zip(e_lags, theta[len(proc_idx) :]):
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
        if optimise and not _invertible(split(x0)[1]):
            # ELS gave an unstable noise model: start PEM from C = 1 instead.
            x0[len(proc_idx) :] = 0.0
        if optimise:
            x, notes = x0, []
            for attempt in range(PEM_REFLECTIONS + 1):
                sol = _scipy_lsq(
                    residual, x, jac=jac, method="lm", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200 * len(x0)
                )
                x = sol.x
                c = split(x)[1]
                if _invertible(c) or attempt == PEM_REFLECTIONS:
                    break
                # C left the unit circle (Ljung §10.1: the predictor needs 1/C stable). The same noise spectrum
                # has C with those roots reflected inside (up to a gain), so restart from it.
                x = x.copy()
                x[len(proc_idx) :] = reflect_inside(c)[e_lags]
                notes.append("C reflected inside the unit circle, PEM restarted")
            message = "; ".join([str(sol.message), *notes])
            if not _invertible(split(x)[1]):
                # PEM keeps returning to a non-invertible C: of its estimate with C reflected and the ELS estimate
                # (when invertible), keep the one with the smaller prediction error.
                xr = x.copy()
                xr[len(proc_idx) :] = reflect_inside(split(x)[1])[e_lags]
                cands = [(xr, "PEM with C reflected")] + (
                    [(x0.copy(), "the ELS estimate")] if _invertible(split(x0)[1]) else []
                )
                x, which = min(cands, key=lambda cnd: float(np.sum(residual(cnd[0]) ** 2)))
                message += f"; C stayed outside the unit circle after {PEM_REFLECTIONS} restarts: kept {which}"
            r, J = residual(x), jac(x)
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
        theta = np.empty(len(terms))
        stderr = np.empty(len(terms))
        order = proc_idx + idx["e"]
        theta[order] = x
        stderr[order] = se
        if not _invertible(split(x)[1]):
            raise DataError(
                f"armax ({self.method}): the fit gave a noise polynomial C with roots outside the "
                "unit circle (non-invertible); try method=els or other orders"
            )
        return theta, stderr, message

    def _extra_state(self) -> dict[str, Any]:
        return {"chosen_orders": dict(self.chosen_orders_)} if getattr(self, "chosen_orders_", None) else {}

    def _load_extra(self, extra: dict[str, Any]) -> None:
        self.chosen_orders_ = dict(extra.get("chosen_orders", {}))
