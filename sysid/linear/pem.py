"""Output-error and Box–Jenkins models by the prediction-error method (registry ids ``oe``, ``bj``).

Model (Ljung, *System Identification*, 2nd ed., §4.2, eq. 4.40/4.41), one output, m ≥ 1 inputs::

    y(t) = Σ_i B_i(q)/F_i(q) u_i(t − nk_i) + C(q)/D(q) e(t)

in MATLAB's convention (B_i = b1 + b2 q⁻¹ + …, F_i, C, D monic); OE is C = D = 1.

Estimation minimises Σ ε(t, θ)², ε = D/C · [y − Σ_i B_i/F_i u_i(t − nk_i)] (eq. 4.43, 7.12), by
Levenberg–Marquardt with the analytic Jacobian (§10.2, eq. 10.42: each column a regressor through the model's
filters, from zero initial conditions). F_i, C, D keep their roots inside the unit circle: initial values are
reflected (r → 1/r̄) and a step to an unstable polynomial is refused.

Initialisation (§7.6): per input the simplified refined IV (Steiglitz–McBride with instruments from the
simulated output), several inputs by back-fitting; BJ then fits C/D to the OE residual by Hannan–Rissanen.

Uncertainty: P = σ̂² (JᵀJ)⁻¹, σ̂² = V/(N − p) (eq. 9.17/9.18), valid for OE under white disturbance and for BJ
with the right noise model. Orders left ``None`` are chosen by :mod:`sysid.linear.order`, ``nk=None`` by
:func:`sysid.linear.order.delay_estimate`. Prediction: free run x = Σ B_i/F_i u_i from the initial filter state
fitted to the first ``max_lag_`` samples; k-step (§3.2, eq. 3.31) ŷ(t|t−k) = y − W_k·(y − x), W_k = H̄_k D/C.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.optimize import least_squares as _scipy_lsq
from scipy.signal import lfilter

from sysid.base import Identifier, as_record_list, check_prediction, check_records, stop_at_divergence
from sysid.data.record import Record
from sysid.errors import ConfigError
from sysid.linear.pem_init import hannan_rissanen, is_stable, oe_sim, shift, sriv, stabilise
from sysid.linear.uncertainty import monte_carlo_band, poles_with_std, tf_response_with_std

__all__ = ["OE", "BJ", "sriv", "stabilise"]

DIVERGENCE_FACTOR = 1e3
BACKFIT_SWEEPS = 3


# --------------------------------------------------------------------------------------- helpers
def _orders(value: Any, m: int, name: str) -> list[int] | None:
    """``None`` (choose automatically), an int for every input, or one per input (list / "2-3" string)."""
    if value is None:
        return None
    if isinstance(value, str):
        if value.lower() in ("none", "auto"):
            return None
        value = [v for v in value.replace(";", "-").split("-") if v]
    vals = list(value) if isinstance(value, (list, tuple, np.ndarray)) else [value]
    try:
        out = [int(v) for v in vals]
        if any(float(v) != int(float(v)) for v in vals):
            raise ValueError
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: expected a non-negative integer (or one per input), got {value!r}") from None
    if len(out) == 1:
        out = out * m
    if len(out) != m:
        raise ConfigError(f"{name}: {len(out)} values given for {m} inputs")
    if any(v < 0 for v in out):
        raise ConfigError(f"{name} must be >= 0, got {value!r}")
    return out


# --------------------------------------------------------------------------------------- the models
class _PolyPEM(Identifier):
    """Shared machinery of OE and BJ (module docstring). Subclasses set ``_noise`` (False for OE)."""

    _noise = False

    # ---- orders
    def _resolve_orders(self, records: list[Record]) -> dict[str, Any]:
        m = records[0].n_inputs
        nk = _orders(self.nk, m, "nk")
        chosen: dict[str, Any] = {}
        if nk is None:
            from sysid.linear.order import delay_estimate

            nk = [int(v) for v in delay_estimate(records)]
            chosen["nk"] = nk
        nb, nf = _orders(self.nb, m, "nb"), _orders(self.nf, m, "nf")
        nc: int | None = 0
        nd: int | None = 0
        if self._noise:
            nc = self.nc if self.nc is not None else None
            nd = self.nd if self.nd is not None else None
        if nb is None or nf is None:
            from sysid.linear.order import select_oe_orders

            n, table, self.order_search_ = select_oe_orders(records, nk, max_order=int(self.max_order), nb=nb, nf=nf)
            nb = nb if nb is not None else [n] * m
            nf = nf if nf is not None else [n] * m
            chosen.update(nb=nb, nf=nf)
            self.order_table_ = table
        if self._noise and (nc is None or nd is None):
            nc, nd = self._choose_noise_orders(records, nb, nf, nk, nc, nd)
            chosen.update(nc=nc, nd=nd)
        for k, v in (("nc", nc), ("nd", nd)):
            if v is None or int(v) < 0 or int(v) != v:
                raise ConfigError(f"{self.name}: {k} must be a non-negative integer, got {v!r}")
        if sum(nb) == 0:
            raise ConfigError(f"{self.name}: nb = 0 for every input leaves no input dynamics to estimate")
        return {"nb": nb, "nf": nf, "nk": nk, "nc": int(nc or 0), "nd": int(nd or 0), "chosen": chosen}

    def _choose_noise_orders(self, records, nb, nf, nk, nc, nd):
        """nc = nd by BIC of the Hannan–Rissanen ARMA fit to the OE residual, over 0..4."""
        bs, fs = self._init_g(records, nb, nf, nk)
        vs = [self._v(r, bs, fs, nk) for r in records]
        n = sum(v.size for v in vs)
        best = (np.inf, 0, 0)
        for k in range(0, 5):
            cc = nc if nc is not None else k
            dd = nd if nd is not None else k
            c, d = hannan_rissanen(vs, cc, dd)
            e = np.concatenate([lfilter(d, c, v) for v in vs])
            bic = n * np.log(max(float(e @ e) / n, 1e-300)) + (cc + dd) * np.log(n)
            if bic < best[0] or k == 0:
                best = (bic, cc, dd)
        return best[1], best[2]

    # ---- fitting
    def _init_g(self, records, nb, nf, nk):
        m = records[0].n_inputs
        us = [r.u.reshape(len(r), -1) for r in records]
        ys = [r.output.reshape(-1) for r in records]
        bs = [np.zeros(nb[i]) for i in range(m)]
        fs = [np.ones(nf[i] + 1) for i in range(m)]
        X = [np.zeros((len(r), m)) for r in records]
        for _ in range(BACKFIT_SWEEPS if m > 1 else 1):
            for i in range(m):
                tgt = [y_ - x_.sum(axis=1) + x_[:, i] for y_, x_ in zip(ys, X)]
                if nb[i] == 0:
                    continue
                bs[i], fs[i] = sriv([u_[:, i] for u_ in us], tgt, nb[i], nf[i], nk[i])
                for u_, x_ in zip(us, X):
                    x_[:, i] = oe_sim(bs[i], fs[i], nk[i], u_[:, i])
        return bs, fs

    def _v(self, rec, bs, fs, nk):
        u = rec.u.reshape(len(rec), -1)
        return rec.y.reshape(-1) - sum(oe_sim(bs[i], fs[i], nk[i], u[:, i]) for i in range(len(bs)))

    def _layout(self, o) -> list[tuple[str, int, int]]:
        """(kind, input index, k) per parameter, in θ order: per input b1..b_nb, f1..f_nf; then c…, d…."""
        lay = []
        for i in range(len(o["nb"])):
            lay += [("b", i, k) for k in range(1, o["nb"][i] + 1)]
            lay += [("f", i, k) for k in range(1, o["nf"][i] + 1)]
        lay += [("c", -1, k) for k in range(1, o["nc"] + 1)]
        lay += [("d", -1, k) for k in range(1, o["nd"] + 1)]
        return lay

    def _unpack(self, theta, o):
        bs, fs, j = [], [], 0
        for i in range(len(o["nb"])):
            bs.append(np.asarray(theta[j : j + o["nb"][i]], float))
            j += o["nb"][i]
            fs.append(np.concatenate([[1.0], theta[j : j + o["nf"][i]]]))
            j += o["nf"][i]
        c = np.concatenate([[1.0], theta[j : j + o["nc"]]])
        j += o["nc"]
        d = np.concatenate([[1.0], theta[j : j + o["nd"]]])
        return bs, fs, c, d

    def fit(self, data: Record | Sequence[Record]) -> _PolyPEM:
        records = as_record_list(data)
        if records[0].n_outputs != 1:
            raise ConfigError(
                f"{self.name}: one output supported (MISO), the data have {records[0].n_outputs}; "
                "use n4sid for several outputs"
            )
        if int(self.max_iter) < 0:
            raise ConfigError(f"{self.name}: max_iter must be >= 0, got {self.max_iter}")
        o = self._resolve_orders(records)
        lay = self._layout(o)
        L0 = max([o["nk"][i] + o["nb"][i] for i in range(len(o["nb"]))] + o["nf"] + [o["nc"], o["nd"]])
        check_records(records, L0, len(lay) + 1, self.name)
        bs, fs = self._init_g(records, o["nb"], o["nf"], o["nk"])
        c = d = np.ones(1)
        if self._noise:
            c, d = hannan_rissanen([self._v(r, bs, fs, o["nk"]) for r in records], o["nc"], o["nd"])
        theta0 = np.concatenate([np.concatenate([bs[i], fs[i][1:]]) for i in range(len(bs))] + [c[1:], d[1:]])
        us = [r.u.reshape(len(r), -1) for r in records]
        ys = [r.output.reshape(-1) for r in records]
        n_res = sum(len(r) for r in records)
        penalty = 1e3 * (max(float(np.std(np.concatenate(ys))), 1e-300) + float(np.max(np.abs(np.concatenate(ys)))))

        def parts(theta):
            bs, fs, c, d = self._unpack(theta, o)
            if not all(is_stable(p) for p in fs + [c, d]):
                return None
            out = []
            for u_, y_ in zip(us, ys):
                X = np.column_stack([oe_sim(bs[i], fs[i], o["nk"][i], u_[:, i]) for i in range(len(bs))])
                v = y_ - X.sum(axis=1)
                e = lfilter(d, c, v) if self._noise else v
                out.append((u_, X, v, e))
            return bs, fs, c, d, out

        def residual(theta):
            p = parts(theta)
            if p is None:
                return np.full(n_res, penalty)
            r = np.concatenate([e for *_, e in p[4]])
            return r if np.isfinite(r).all() else np.full(n_res, penalty)

        def jac(theta):
            p = parts(theta)
            if p is None:  # pragma: no cover - LM evaluates the Jacobian only at accepted (stable) points
                return np.zeros((n_res, len(lay)))
            bs, fs, c, d, out = p
            blocks = []
            for u_, X, v, e in out:
                J = np.empty((len(e), len(lay)))
                cache: dict[Any, np.ndarray] = {}
                for j, (kind, i, k) in enumerate(lay):
                    if kind in ("b", "f"):
                        if (kind, i) not in cache:
                            den = np.convolve(c, fs[i]) if self._noise else fs[i]
                            num = d if self._noise else [1.0]
                            src = u_[:, i] if kind == "b" else X[:, i]
                            cache[(kind, i)] = lfilter(num, den, src)
                        w = cache[(kind, i)]
                        J[:, j] = -shift(w, o["nk"][i] + k - 1) if kind == "b" else shift(w, k)
                    elif kind == "c":
                        if "c" not in cache:
                            cache["c"] = lfilter([1.0], c, e)
                        J[:, j] = -shift(cache["c"], k)
                    else:
                        if "d" not in cache:
                            cache["d"] = lfilter([1.0], c, v)
                        J[:, j] = shift(cache["d"], k)
                blocks.append(J)
            return np.vstack(blocks)

        status = "initial estimate (max_iter=0)"
        theta = theta0
        if int(self.max_iter) > 0:
            sol = _scipy_lsq(
                residual,
                theta0,
                jac=jac,
                method="lm",
                x_scale="jac",
                xtol=1e-10,
                ftol=1e-10,
                gtol=1e-10,
                max_nfev=int(self.max_iter),
            )
            if np.sum(sol.fun**2) <= np.sum(residual(theta0) ** 2):
                theta, status = sol.x, str(sol.message)
        r = residual(theta)
        J = jac(theta)
        n, p = r.size, theta.size
        sigma2 = float(r @ r) / max(n - p, 1)
        try:
            cov = sigma2 * np.linalg.inv(J.T @ J)
        except np.linalg.LinAlgError:
            cov = sigma2 * np.linalg.pinv(J.T @ J)
        bs, fs, c, d = self._unpack(theta, o)
        self.orders_ = {k: o[k] for k in ("nb", "nf", "nk", "nc", "nd")}
        self.chosen_orders_ = o["chosen"]
        self.b_, self.f_, self.c_, self.d_ = bs, fs, c, d
        self.theta_, self.cov_, self.noise_variance_ = theta, cov, sigma2
        self.layout_ = lay
        self.pem_status_ = status
        self._set_common(records)
        return self

    def _set_common(self, records) -> None:
        self.n_inputs_ = len(self.b_)
        self.n_outputs_ = 1
        self.n_parameters_ = len(self.theta_)
        states = sum(max(self.orders_["nk"][i] + len(self.b_[i]), len(self.f_[i])) - 1 for i in range(self.n_inputs_))
        self.n_states_ = int(states)
        self.max_lag_ = int(max(2 * states, max(self.orders_["nc"], self.orders_["nd"])))
        if records is not None:
            self.y_bound_ = DIVERGENCE_FACTOR * max(max(float(np.max(np.abs(r.y))) for r in records), 1e-300)
        self.diverged_at_ = None

    # ---- prediction
    def _check_fitted(self) -> None:
        if not hasattr(self, "theta_"):
            raise ConfigError(f"{self.name}: model is not fitted (call fit first)")

    def _simulate(self, u: np.ndarray, y: np.ndarray | None, bs=None, fs=None) -> np.ndarray:
        """Σ B_i/F_i u_i(t − nk_i), initial filter state fitted to the first max_lag_ samples of y (if given)."""
        bs = self.b_ if bs is None else bs
        fs = self.f_ if fs is None else fs
        nk = self.orders_["nk"]
        N = u.shape[0]
        x = np.zeros(N)
        L = min(self.max_lag_, N) if y is not None else 0
        coeff, basis = [], []
        for i in range(len(bs)):
            bb = np.concatenate([np.zeros(nk[i]), bs[i]])
            s = max(bb.size, fs[i].size) - 1
            coeff.append((bb, s))
            if L > 0 and s > 0:
                for j in range(s):
                    zi = np.zeros(s)
                    zi[j] = 1.0
                    basis.append((i, j, lfilter(bb, fs[i], np.zeros(L), zi=zi)[0]))
        zis = [np.zeros(s) for _, s in coeff]
        if basis and y is not None:  # basis is built only when y is given (L > 0)
            x0 = sum(lfilter(coeff[i][0], fs[i], u[:L, i]) for i in range(len(bs)))
            Phi = np.column_stack([b for *_, b in basis])
            z = np.linalg.lstsq(Phi, y[:L] - x0, rcond=None)[0]
            for (i, j, _), zj in zip(basis, z):
                zis[i][j] = zj
        for i in range(len(bs)):
            bb, s = coeff[i]
            x += lfilter(bb, fs[i], u[:, i], zi=zis[i])[0] if s > 0 else lfilter(bb, fs[i], u[:, i])
        return x

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """One-step (``horizon=1``), k-step at every sample (``horizon=k``) or free run (``None``); module docstring."""
        self._check_fitted()
        check_prediction(self, record, horizon)
        u = record.u.reshape(len(record), -1)
        y = record.output.reshape(-1)
        x = self._simulate(u, y)
        if horizon is None or not self._noise:
            yhat = x
        else:
            h = lfilter(self.c_, self.d_, np.r_[1.0, np.zeros(int(horizon) - 1)])
            yhat = y - lfilter(np.convolve(h, self.d_), self.c_, y - x)
        yhat = np.array(yhat, float)
        L = min(self.max_lag_, len(y))
        yhat[:L] = y[:L]
        return stop_at_divergence(self, yhat).reshape(record.output.shape)

    # ---- reporting
    def parameter_names(self) -> list[str]:
        m = len(self.orders_["nb"])
        return [f"{kind}{k}" + (f"_u{i + 1}" if m > 1 and i >= 0 else "") for kind, i, k in self.layout_]

    def parameters(self) -> list[dict[str, Any]]:
        """``[{"name": "b1", "value", "std"}]`` in θ order (module docstring for the polynomial convention)."""
        self._check_fitted()
        std = np.sqrt(np.maximum(np.diag(self.cov_), 0.0))
        return [
            {"name": n, "value": float(v), "std": float(s)} for n, v, s in zip(self.parameter_names(), self.theta_, std)
        ]

    def _index(self, kind: str, i: int) -> list[int]:
        return [j for j, (kd, ii, _) in enumerate(self.layout_) if kd == kind and ii == i]

    def poles(self) -> list[dict[str, float | None]]:
        """Poles of G (roots of every F_i) with their complex std (:func:`sysid.linear.uncertainty.poles_with_std`)."""
        self._check_fitted()
        out = []
        for i, f in enumerate(self.f_):
            idx = self._index("f", i)
            for p in poles_with_std(f, self.cov_[np.ix_(idx, idx)]):
                out.append({**p, "input": i + 1} if len(self.f_) > 1 else p)
        return out

    def frequency_response(self, f_hz: np.ndarray, fs: float, input: int = 0) -> dict[str, np.ndarray]:
        """G_i(e^{iωT}) at ``f_hz`` [Hz] for sampling rate ``fs`` [Hz], with its complex std (``std``)."""
        self._check_fitted()
        idx = self._index("b", input) + self._index("f", input)
        G, std = tf_response_with_std(
            self.b_[input],
            self.f_[input],
            self.orders_["nk"][input],
            2 * np.pi * np.asarray(f_hz, float) / fs,
            self.cov_[np.ix_(idx, idx)],
        )
        if std is None:  # tf_response_with_std returns it whenever a covariance is given
            raise RuntimeError("no standard deviation from the parameter covariance")
        return {"f_hz": np.asarray(f_hz, float), "G": G, "std": std}

    def simulation_band(self, record: Record, n_draws: int = 100, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Mean and std per sample of the free-run output over parameter draws from N(θ̂, P) (Monte Carlo)."""
        self._check_fitted()
        u = record.u.reshape(len(record), -1)
        y = record.output.reshape(-1)
        idx = [j for j, (kd, _, _) in enumerate(self.layout_) if kd in ("b", "f")]

        def sim(th_g):
            th = self.theta_.copy()
            th[idx] = th_g
            o = {**self.orders_}
            bs, fs, _, _ = self._unpack(th, o)
            if not all(is_stable(f) for f in fs):
                return np.full(len(y), np.nan)
            return self._simulate(u, y, bs, fs)

        return monte_carlo_band(sim, self.theta_[idx], self.cov_[np.ix_(idx, idx)], n_draws, seed)

    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "theta_"):
            d.update(
                parameters=self.parameters(),
                poles=self.poles(),
                orders=self.orders_,
                chosen_orders=self.chosen_orders_,
                noise_variance=self.noise_variance_,
                pem=self.pem_status_,
                max_lag=self.max_lag_,
                terms=[],
            )
            if getattr(self, "order_table_", None):
                d["order_selection"] = self.order_table_
        return d

    def summary(self) -> str:
        lines = [
            f"{self.name}: orders "
            + ", ".join(f"{k}={v}" for k, v in self.orders_.items())
            + (f" (chosen automatically: {', '.join(self.chosen_orders_)})" if self.chosen_orders_ else "")
        ]
        for p in self.parameters():
            lines.append(f"  {p['name']:<8} {p['value']: .6g} ± {p['std']:.2g}")
        return "\n".join(lines)

    # ---- persistence
    def _state(self) -> dict[str, Any]:
        return {
            "orders": self.orders_,
            "chosen": self.chosen_orders_,
            "theta": self.theta_.tolist(),
            "cov": self.cov_.tolist(),
            "layout": [list(t) for t in self.layout_],
            "noise_variance": self.noise_variance_,
            "y_bound": self.y_bound_,
            "pem": self.pem_status_,
        }

    def _load_state(self, state: dict[str, Any]) -> None:
        self.orders_ = {k: v for k, v in state["orders"].items()}
        self.chosen_orders_ = dict(state.get("chosen", {}))
        self.theta_ = np.asarray(state["theta"], float)
        self.cov_ = np.asarray(state["cov"], float)
        self.layout_ = [(str(a), int(b), int(c)) for a, b, c in state["layout"]]
        self.noise_variance_ = float(state["noise_variance"])
        self.pem_status_ = str(state.get("pem", ""))
        self.b_, self.f_, self.c_, self.d_ = self._unpack(self.theta_, self.orders_)
        self.y_bound_ = float(state["y_bound"])
        self._set_common(None)


class OE(_PolyPEM):
    """Output-error model y = Σ B_i/F_i u_i(t − nk_i) + e by PEM (module docstring).

    Parameters: ``nb``, ``nf``, ``nk`` (MATLAB names; an int for every input or one per input as ``2-3``;
    ``None`` = chosen automatically and reported); ``max_order`` (largest order of the automatic search);
    ``max_iter`` (most residual evaluations of Levenberg–Marquardt; 0 keeps the IV initial estimate).
    """

    name = "oe"

    def __init__(self, nb: Any = None, nf: Any = None, nk: Any = None, max_order: int = 24, max_iter: int = 200):
        self.nb = nb
        self.nf = nf
        self.nk = nk
        self.max_order = max_order
        self.max_iter = max_iter


class BJ(_PolyPEM):
    """Box–Jenkins model y = Σ B_i/F_i u_i(t − nk_i) + C/D e by PEM (module docstring). Options as :class:`OE`
    plus ``nc``, ``nd`` (noise-model orders; ``None``: chosen by BIC of the residual's ARMA fit, 0..4)."""

    name = "bj"
    _noise = True

    def __init__(
        self,
        nb: Any = None,
        nc: Any = None,
        nd: Any = None,
        nf: Any = None,
        nk: Any = None,
        max_order: int = 24,
        max_iter: int = 200,
    ):
        self.nb = nb
        self.nc = nc
        self.nd = nd
        self.nf = nf
        self.nk = nk
        self.max_order = max_order
        self.max_iter = max_iter
