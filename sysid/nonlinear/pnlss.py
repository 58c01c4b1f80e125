"""Polynomial nonlinear state-space model started from the best linear approximation (registry id ``pnlss``).

Model (Paduart et al., "Identification of nonlinear systems using polynomial nonlinear state space models",
Automatica 46 (2010) 647-656, eq. 3)::

    x(t+1) = A x(t) + B u(t) + E ζ(x(t), u(t)),      y(t) = C x(t) + D u(t) + F η(x(t), u(t))

with ζ the monomials of z = [x; u] of degree 2 … ``degree``, η those of degree 2 … ``output_degree`` (after the
constant 1 with ``constant``; :mod:`sysid.nonlinear.pnlss_sim`). The procedure is the paper's §4:

1. **Linear start** (§4.1): (A, B, C, D) from the subspace model (:class:`sysid.linear.subspace.N4SID`, order
   ``nx``; B and D by output-error least squares), E = F = 0; states scaled to unit RMS in the linear
   simulation, u and y by their RMS, so that monomials of every degree are of order one.
2. **Nonlinear optimisation** (§4.2): every parameter and each record's x(0) minimise the simulation error
   (:func:`scipy.optimize.least_squares`) with the exact Jacobian of the forward sensitivities (eq. 18-20,
   compiled). ``starts`` searches take different paths; the lowest cost among those that converged is kept
   (a search cut by ``max_nfev`` ends where the last bits of its start lead), ties within ``COST_RTOL`` in
   search order. A step whose simulation leaves ±``DIVERGENCE_FACTOR`` × max|y| is rejected; a result worse
   than the linear start is never returned. With ``val_fraction`` the θ with the lowest hold-out RMSE is kept
   and ``patience`` stops the search.

Prediction is a free run (every ``horizon`` alike) from the initial state fitted to the first ``max_lag_``
measured outputs (least squares on the nonlinear free run, a small ridge towards the estimation records' mean
initial state); without y, from that mean state. Measurements behind these choices: docs/identifiers.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from sysid.base import Identifier, as_record_list, check_prediction, check_records, stop_at_divergence
from sysid.config import int_option
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.nonlinear import pnlss_sim as ps

__all__ = ["PNLSS"]

DIVERGENCE_FACTOR = 1e3  # a simulation leaving this multiple of max|y| (or of the states' RMS, 1) has diverged
DIVERGED_RESIDUAL = 1e3  # residual (in output RMS) of every sample from a divergence on
X0_ITERATIONS = 20  # most evaluations of the initial-state fit in predict
X0_RIDGE = 1e-2  # weight of the initial-state prior (states and outputs are in RMS units)
COST_RTOL = 1e-6  # searches whose final costs differ by less (relative) are tied: the first in SEARCHES order is kept
# The searches run by ``starts`` (scipy least_squares method, x_scale), in this order, all from the linear start:
# other paths (trust region shapes) to a minimum; the lowest cost (hold-out RMSE when held out) of the converged
# searches is kept (of all, when none converged).
SEARCHES = (("trf", "jac"), ("lm", "jac"), ("lm", 1.0))
MONOMIALS_OF = ("xu", "x")  # the variables ζ and η are monomials of (option ``monomials_of``)


class _Stop(Exception):
    """Raised inside the residual to end the search early (hold-out patience exhausted)."""


def _int_option(name: str, value: Any, low: int) -> int:
    return int_option("pnlss", name, value, low)


class PNLSS(Identifier):
    """Polynomial nonlinear state space, linear part from the subspace model, all parameters on simulation error.

    Parameters
    ----------
    nx : int
        State dimension.
    degree, output_degree : int, int or None
        Highest total degree of the monomials of (x, u) in the state equation (1: linear) and in the output
        equation (``None``: ``degree``).
    max_nfev : int
        Most simulations of each search (0: the linear start is the model).
    xtol, ftol : float
        Relative step / cost tolerances of the search (scipy's ``least_squares``).
    val_fraction, patience : float, int
        Last share (0 … 0.5) of the last record held out for model selection, and evaluations without a better
        hold-out RMSE before the search stops (0: none).
    starts : int
        Searches from the linear start (:data:`SEARCHES`: trust-region reflective and Levenberg–Marquardt scaled
        by the Jacobian's columns, then LM unscaled), 1 … 3: one search can stop in a local minimum.
    constant : bool
        Add the constant 1 to η: an output offset (measured data keep their means).
    monomials_of : str
        ``xu``: ζ and η are monomials of (x, u) (the paper's); ``x``: of the states alone, the input entering
        through B u and D u only (fewer parameters; a continuous-time system affine in its input, such as a Duffing
        oscillator, is so only approximately once sampled: measured on Silverbox and a simulated Duffing
        oscillator in docs/benchmarks-sota.md).
    """

    name = "pnlss"

    def __init__(
        self,
        nx: int = 2,
        degree: int = 3,
        output_degree: int | None = None,
        max_nfev: int = 100,
        xtol: float = 1e-10,
        ftol: float = 1e-10,
        val_fraction: float = 0.0,
        patience: int = 0,
        starts: int = 2,
        constant: bool = True,
        monomials_of: str = "xu",
    ):
        self.nx = nx
        self.degree = degree
        self.output_degree = output_degree
        self.max_nfev = max_nfev
        self.xtol = xtol
        self.ftol = ftol
        self.val_fraction = val_fraction
        self.patience = patience
        self.starts = starts
        self.constant = constant
        self.monomials_of = monomials_of

    # ------------------------------------------------------------------ options
    def _check_options(self) -> tuple[int, int, int]:
        n = _int_option("nx", self.nx, 1)
        d = _int_option("degree", self.degree, 1)
        do = d if self.output_degree is None else _int_option("output_degree", self.output_degree, 1)
        _int_option("max_nfev", self.max_nfev, 0)
        _int_option("patience", self.patience, 0)
        if _int_option("starts", self.starts, 1) > len(SEARCHES):
            raise ConfigError(f"pnlss: starts={self.starts!r} must be at most {len(SEARCHES)}")
        for key in ("xtol", "ftol"):
            v = getattr(self, key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < 1:
                raise ConfigError(f"pnlss: {key}={v!r} must lie in (0, 1)")
        v = self.val_fraction
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v <= 0.5:
            raise ConfigError(f"pnlss: val_fraction={v!r} must be a fraction in [0, 0.5]")
        return n, d, do

    # ------------------------------------------------------------------ parameter vector
    def _pack(self) -> np.ndarray:
        return np.concatenate([M.reshape(-1) for M in (self.A_, self.B_, self.E_, self.C_, self.D_, self.F_)])

    def _unpack(self, theta: np.ndarray) -> tuple[np.ndarray, ...]:
        n, m, p = self.nx_, self.n_inputs_, self.n_outputs_
        shapes = [(n, n), (n, m), (n, self.facE_.shape[0]), (p, n), (p, m), (p, self.facF_.shape[0])]
        out, k = [], 0
        for s in shapes:
            size = s[0] * s[1]
            out.append(theta[k : k + size].reshape(s))
            k += size
        return tuple(out)

    def _run(self, theta: np.ndarray, u: np.ndarray, x0: np.ndarray, jacobian: bool):
        A, B, E, C, D, F = self._unpack(theta)
        return ps.simulate(A, B, C, D, E, F, self.facE_, self.facF_, u, x0, self.bound_, jacobian)

    # ------------------------------------------------------------------ fitting
    def fit(self, data: Record | Sequence[Record]) -> PNLSS:
        from sysid.linear.subspace import N4SID

        records = as_record_list(data)
        n, d, do = self._check_options()
        m, p = records[0].n_inputs, records[0].n_outputs
        self.nx_, self.n_inputs_, self.n_outputs_ = n, m, p
        if not isinstance(self.constant, (bool, np.bool_)):
            raise ConfigError(f"pnlss: constant={self.constant!r} must be true or false")
        c = bool(self.constant)
        if self.monomials_of not in MONOMIALS_OF:
            raise ConfigError(f"pnlss: monomials_of={self.monomials_of!r} not one of: {', '.join(MONOMIALS_OF)}")
        self.facE_, self.facF_ = ps.monomials(n + m, d), ps.monomials(n + m, do, c)
        if self.monomials_of == "x":  # rows whose factors are all states (-1 pads; the constant is all pads)
            self.facE_, self.facF_ = (f[np.all(f < n, axis=1)] for f in (self.facE_, self.facF_))
        n_par = ps.n_state_params(n, m, self.facE_.shape[0]) + ps.n_output_params(n, m, p, self.facF_.shape[0])
        check_records(records, 2 * n, n_par + n * len(records) + 1, self.name)
        us = [r.u.reshape(len(r), -1).astype(float) for r in records]
        ys = [r.output.reshape(len(r), -1).astype(float) for r in records]
        self.u_scale_ = np.sqrt(np.mean(np.vstack(us) ** 2, axis=0))
        self.y_scale_ = np.sqrt(np.mean(np.vstack(ys) ** 2, axis=0))
        us = [u / self.u_scale_ for u in us]
        ys = [y / self.y_scale_ for y in ys]
        cut = len(ys[-1])
        if self.val_fraction:
            cut = len(ys[-1]) - int(round(float(self.val_fraction) * len(ys[-1])))
            if cut <= 2 * n or cut == len(ys[-1]):
                raise DataError(
                    f"pnlss: val_fraction={self.val_fraction} leaves {cut} estimation samples of "
                    f"{len(ys[-1])} in the last record (need more than {2 * n} and a hold-out of >= 1)"
                )
        self.bound_ = DIVERGENCE_FACTOR * max(float(np.max(np.abs(np.vstack(ys)))), 1.0)
        # 1. linear start: subspace model of the estimation part, states scaled to unit RMS
        # (with the constant: of the data less their means, the output's constant then giving the mean output)
        parts = list(zip(us[:-1] + [us[-1][:cut]], ys[:-1] + [ys[-1][:cut]]))
        u_mean, y_mean = (np.mean(np.vstack([q[k] for q in parts]), axis=0) * c for k in (0, 1))
        lin = N4SID(nx=n, focus="simulation").fit(
            [Record(u=u - u_mean, y=y - y_mean, fs=records[0].fs) for u, y in parts]
        )
        self.A_, self.B_, self.C_, self.D_ = (np.asarray(getattr(lin, k + "_"), float) for k in "ABCD")
        self.E_ = np.zeros((n, self.facE_.shape[0]))
        self.F_ = np.zeros((p, self.facF_.shape[0]))
        if c:  # static gain G(1) = C (I − A)⁻¹ B + D; the output constant makes G(1) ū + f0 = ȳ
            gain = self.C_ @ np.linalg.lstsq(np.eye(n) - self.A_, self.B_, rcond=None)[0] + self.D_
            self.F_[:, 0] = y_mean - gain @ u_mean
        self._balance(us)
        self.linear_ = {k: getattr(self, k + "_").copy() for k in "ABCD"}
        self._optimise(us, ys, cut)
        self.n_parameters_ = int(n_par)
        self._set_common()
        return self

    def _set_common(self) -> None:
        self.max_lag_ = int(2 * math.ceil(self.nx_ / self.n_outputs_))
        self.y_bound_ = self.bound_ * float(np.max(self.y_scale_))  # nan (a diverged compiled run) is outside too
        self.diverged_at_ = None

    def _balance(self, us: list[np.ndarray]) -> None:
        """Similarity transform x → T⁻¹x with T = diag(RMS of each state of the linear simulation)."""
        n, m = self.nx_, self.n_inputs_
        none = np.zeros((n, 0)), np.zeros((n, 0))
        xs = [
            ps.simulate(self.A_, self.B_, np.eye(n), np.zeros((n, m)), *none, self.facE_[:0], self.facF_[:0], u)[0]
            for u in us
        ]
        rms = np.sqrt(np.mean(np.vstack(xs) ** 2, axis=0))
        T = np.where(np.isfinite(rms) & (rms > 0), rms, 1.0)
        self.A_ = self.A_ * T[None, :] / T[:, None]
        self.B_ = self.B_ / T[:, None]
        self.C_ = self.C_ * T[None, :]

    def _optimise(self, us, ys, cut: int) -> None:
        n, R = self.nx_, len(us)
        theta0 = self._pack()
        P = theta0.size
        Ps = ps.n_state_params(n, self.n_inputs_, self.facE_.shape[0])
        val_n = len(ys[-1]) - cut
        best: dict[str, Any] = {"rms": np.inf, "theta": None, "since": 0}
        jac_cache: dict[str, Any] = {}

        def split(z):
            return z[:P], z[P:].reshape(R, n)

        def evaluate(z, jacobian):
            theta, x0s = split(z)
            res, jac, val_err = [], [], None
            for r, (u, y) in enumerate(zip(us, ys)):
                yh, J, div = self._run(theta, u, x0s[r], jacobian)
                e = yh - y
                stop = cut if r == R - 1 else len(y)
                if r == R - 1 and val_n:
                    tail = e[cut:]
                    val_err = float(np.sqrt(np.mean(tail**2))) if np.isfinite(tail).all() else np.inf
                e = e[:stop]
                if div >= 0:
                    e[div:] = DIVERGED_RESIDUAL
                res.append(e.reshape(-1))
                if jacobian:
                    Jg = np.zeros((stop, y.shape[1], P + R * n))
                    Jg[:, :, :Ps] = J[:stop, :, :Ps]
                    Jg[:, :, P + r * n : P + (r + 1) * n] = J[:stop, :, Ps : Ps + n]
                    Jg[:, :, Ps:P] = J[:stop, :, Ps + n :]
                    if div >= 0:
                        Jg[div:] = 0.0
                    jac.append(Jg.reshape(-1, P + R * n))
            return np.concatenate(res), (np.concatenate(jac) if jacobian else None), val_err

        def fun(z):
            r, _, val_err = evaluate(z, False)
            if val_err is not None:
                if val_err < best["rms"]:
                    best.update(rms=val_err, theta=z.copy(), since=0)
                else:
                    best["since"] += 1
                    if self.patience and best["since"] >= int(self.patience):
                        raise _Stop
            return r

        def jac(z):
            key = z.tobytes()
            if jac_cache.get("key") != key:
                jac_cache.update(key=key, J=evaluate(z, True)[1])
            return jac_cache["J"]

        def search(z0, method, x_scale):
            """One least-squares search from z0; the θ it ends at (or the best on the hold-out) and its costs."""
            best.update(rms=np.inf, theta=None, since=0)
            try:
                sol = least_squares(
                    fun,
                    z0,
                    jac=jac,
                    method=method,
                    x_scale=x_scale,
                    max_nfev=int(self.max_nfev),
                    xtol=float(self.xtol),
                    ftol=float(self.ftol),
                )
                z, status, nfev = sol.x, str(sol.message), int(sol.nfev)
                converged = sol.status > 0  # a tolerance met (0: cut by max_nfev)
            except _Stop:
                z, status, nfev = best["theta"], f"stopped: no better hold-out RMSE in {self.patience} evaluations", -1
                converged = True  # the hold-out rule's own end
            if val_n and best["theta"] is not None:
                z = best["theta"]
            if z is None:  # stopped before any finite hold-out error
                return None
            r1, _, v1 = evaluate(z, False)
            return {
                "method": method,
                "x_scale": x_scale,
                "nfev": nfev,
                "status": status,
                "converged": bool(converged),
                "rms": float(np.sqrt(np.mean(r1**2))),
                "holdout_rms": v1,
                "z": z,
            }

        z0 = np.concatenate([theta0, np.zeros(R * n)])
        r0, _, v0 = evaluate(z0, False)
        rms0 = float(np.sqrt(np.mean(r0**2)))
        runs = [
            search(z0, method, x_scale)
            for method, x_scale in (SEARCHES[: int(self.starts)] if int(self.max_nfev) > 0 else [])
        ]
        runs = [r for r in runs if r is not None and np.isfinite(r["rms"]) and r["rms"] <= rms0]  # never worse
        if runs:  # a search cut by max_nfev competes only when none converged (its end point is path-dependent)
            pool = [r for r in runs if r["converged"]] or runs
            key = "holdout_rms" if val_n else "rms"
            low = min(r[key] for r in pool)
            # costs equal to COST_RTOL are a tie (two paths into one valley), kept in SEARCHES order: the last bits
            # of a cost never choose between two models (their hold-out behaviour can differ)
            pick = next(r for r in pool if r[key] <= low * (1 + COST_RTOL))
        else:
            pick = {"z": z0, "rms": rms0, "status": "kept the linear start", "holdout_rms": v0, "converged": True}
        z = pick["z"]
        theta, x0s = split(z)
        self.A_, self.B_, self.E_, self.C_, self.D_, self.F_ = (M.copy() for M in self._unpack(theta))
        self.x0_ = x0s.copy()
        self.optimisation_ = {
            "rms_linear": rms0,
            "rms": pick["rms"],
            "holdout_rms": pick["holdout_rms"],
            "status": pick["status"],
            "converged": pick["converged"],
            "units": "output RMS",
            "searches": [{k: v for k, v in r.items() if k != "z"} for r in runs],
        }

    # ------------------------------------------------------------------ prediction
    def _check_fitted(self) -> None:
        if not hasattr(self, "A_"):
            raise ConfigError("pnlss: model is not fitted (call fit first)")

    def _initial_state(self, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        """x(0) fitting the first ``max_lag_`` outputs (scaled) by least squares on the nonlinear free run (the
        x(0) columns of the sensitivity Jacobian), with a ridge of weight ``X0_RIDGE`` towards the mean initial
        state of the estimation records: a few samples rarely determine every state (slow modes), and the
        ridge keeps the undetermined directions at a state the system was seen in."""
        n, L = self.nx_, min(self.max_lag_, len(y))
        prior = np.mean(self.x0_, axis=0)
        if L == 0:
            return prior
        theta = self._pack()
        Ps = ps.n_state_params(n, self.n_inputs_, self.facE_.shape[0])

        def res(x):
            yh = self._run(theta, u[:L], x, False)[0]
            e = np.nan_to_num((yh - y[:L]).reshape(-1), nan=DIVERGED_RESIDUAL)
            return np.concatenate([e, X0_RIDGE * (x - prior)])

        def jac(x):
            J = self._run(theta, u[:L], x, True)[1][:, :, Ps : Ps + n].reshape(-1, n)
            return np.vstack([J, X0_RIDGE * np.eye(n)])

        return least_squares(res, prior, jac=jac, method="trf", max_nfev=X0_ITERATIONS).x

    def _simulate(self, u: np.ndarray, y: np.ndarray | None) -> np.ndarray:
        us = u / self.u_scale_
        x0 = np.mean(self.x0_, axis=0) if y is None else self._initial_state(us, y / self.y_scale_)
        yh = self._run(self._pack(), us, x0, False)[0]
        return yh * self.y_scale_

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        """Free-run simulation for every ``horizon`` (output-error model: one-step = k-step = free run)."""
        self._check_fitted()
        check_prediction(self, record, horizon)
        u = record.u.reshape(len(record), -1).astype(float)
        y = record.output.reshape(len(record), -1).astype(float)
        zero = record.meta.get("initial_conditions") == "zero"
        with np.errstate(all="ignore"):
            yhat = self._simulate(u, None if zero else y)
        L = min(self.max_lag_, len(y))
        yhat[:L] = y[:L]
        return stop_at_divergence(self, yhat, "simulation").reshape(record.output.shape)

    # ------------------------------------------------------------------ reporting
    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "A_"):
            n, m = self.nx_, self.n_inputs_
            d.update(
                nx=n,
                degree=int(self.degree),
                monomials_state=ps.monomial_names(self.facE_, n, m),
                monomials_output=ps.monomial_names(self.facF_, n, m),
                poles=[
                    {"re": float(z.real), "im": float(z.imag), "abs": float(abs(z))} for z in np.linalg.eigvals(self.A_)
                ],
                scaling={"u_rms": self.u_scale_.tolist(), "y_rms": self.y_scale_.tolist()},
                state_space={k: getattr(self, k + "_").tolist() for k in "ABCDEF"},
                optimisation=dict(self.optimisation_),
                max_lag=self.max_lag_,
                terms=[],
            )
        return d

    # ------------------------------------------------------------------ persistence
    def _state(self) -> dict[str, Any]:
        out = {k: getattr(self, k + "_").tolist() for k in "ABCDEF"}
        out.update(
            facE=self.facE_.tolist(),
            facF=self.facF_.tolist(),
            u_scale=self.u_scale_.tolist(),
            y_scale=self.y_scale_.tolist(),
            bound=self.bound_,
            x0=self.x0_.tolist(),
            linear={k: v.tolist() for k, v in self.linear_.items()},
            optimisation=self.optimisation_,
        )
        return out

    def _load_state(self, state: dict[str, Any]) -> None:
        for k in "ABCD":
            setattr(self, k + "_", np.asarray(state[k], float))
        self.nx_ = self.A_.shape[0]
        self.n_outputs_, self.n_inputs_ = self.D_.shape
        self.facE_ = np.asarray(state["facE"], np.int64).reshape(-1, max(int(self.degree), 1))
        d_out = int(self.degree if self.output_degree is None else self.output_degree)
        self.facF_ = np.asarray(state["facF"], np.int64).reshape(-1, max(d_out, 1))
        self.E_ = np.asarray(state["E"], float).reshape(self.nx_, self.facE_.shape[0])
        self.F_ = np.asarray(state["F"], float).reshape(self.n_outputs_, self.facF_.shape[0])
        self.u_scale_, self.y_scale_ = np.asarray(state["u_scale"], float), np.asarray(state["y_scale"], float)
        self.bound_ = float(state["bound"])
        self.x0_ = np.asarray(state["x0"], float).reshape(-1, self.nx_)
        self.linear_ = {k: np.asarray(v, float) for k, v in state["linear"].items()}
        self.optimisation_ = dict(state["optimisation"])
        self.n_parameters_ = int(
            self.A_.size + self.B_.size + self.C_.size + self.D_.size + self.E_.size + self.F_.size
        )
        self._set_common()
