"""Polynomial NARX refined on simulation (output) error (registry id ``narx-poly-sim``).

The structure — which polynomial terms of lagged y and u — comes from FROLS and the starting parameters from
least squares, exactly as :class:`sysid.polynomial.NARXPoly` (one-step, equation-error fit, eq. 2-17 … 2-24).
Then every parameter is re-estimated on the free-run error of the estimation data

    θ̂ = argmin_θ  Σ_t ‖ y(t) − ŷ_sim(t; θ) ‖²,   ŷ_sim(t) = Σ_i θ_i p_i(ŷ_sim(t-1…t-ny), u(t-nk…))

(the output-error / simulation-error criterion; Ljung, *System Identification*, 2nd ed. §4.2 and §7.3;
Piroddi & Spinelli 2003 on simulation error for polynomial NARX), started from the measured first ``max_lag``
samples of each record as in the free run of eq. 2-29. The minimisation is Levenberg–Marquardt
(:func:`scipy.optimize.least_squares`, ``method="lm"``) with the exact Jacobian from the forward sensitivity
recursion (compiled with numba)

    S(t) = ∂ŷ(t)/∂θ = p(t) + Σ_i θ_i Σ_{y-factors r of p_i} (∂p_i/∂x_r)(t) · S(t − lag_r)[channel of r],

zero over the initial samples. Under output (measurement) noise the equation-error least squares are biased
(the lagged noisy outputs are regressors) while the simulation-error estimate is consistent when the
structure is right — the test suite checks this on a known polynomial system.

When the least-squares start itself diverges in simulation, the refinement first runs on each record's first n
samples (n = where it diverged, then doubled until the whole record: a continuation in the data length).
A trial parameter vector whose simulation leaves ±``DIVERGENCE_FACTOR`` × max|y| gets a large residual so
that the search rejects it. Standard errors after refinement: σ̂² (JᵀJ)⁻¹ at the optimum (J the simulation
Jacobian), σ̂² the mean squared simulation residual.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit

from sysid.data.record import Record
from sysid.errors import ConfigError
from sysid.polynomial import frols as fr
from sysid.polynomial.model import DIVERGENCE_FACTOR
from sysid.polynomial.narmax import NARXPoly

__all__ = ["NARXPolySim", "simulate_sensitivity"]

DIVERGED_RESIDUAL = 1e3  # residual (in output SDs) given to every sample from a divergence on


@njit(cache=True)
def _sim_sens(y, u, kind, ch, lag, fac, out_of, theta, max_lag, bound, want_jac):  # pragma: no cover - compiled
    N, n_out = y.shape
    P = theta.size
    d_max = fac.shape[1]
    n_reg = kind.size
    yh = y.copy()
    S = np.zeros((N if want_jac else 1, n_out, P))
    x = np.empty(n_reg)
    acc = np.empty(n_out)
    diverged = -1
    for t in range(max_lag, N):
        for r in range(n_reg):
            x[r] = yh[t - lag[r], ch[r]] if kind[r] == 0 else u[t - lag[r], ch[r]]
        for o in range(n_out):
            acc[o] = 0.0
        for i in range(P):
            o = out_of[i]
            v = 1.0
            for j in range(d_max):
                r = fac[i, j]
                if r < 0:
                    break
                v *= x[r]
            acc[o] += theta[i] * v
            if want_jac:
                S[t, o, i] += v
                for j in range(d_max):
                    r = fac[i, j]
                    if r < 0:
                        break
                    if kind[r] != 0:
                        continue
                    p = theta[i]
                    for jj in range(d_max):
                        rr = fac[i, jj]
                        if rr < 0:
                            break
                        if jj != j:
                            p *= x[rr]
                    if p != 0.0:
                        src = t - lag[r]
                        c = ch[r]
                        if src >= max_lag:
                            for q in range(P):
                                S[t, o, q] += p * S[src, c, q]
        bad = False
        for o in range(n_out):
            if not np.isfinite(acc[o]) or abs(acc[o]) > bound:
                bad = True
            yh[t, o] = acc[o]
        if bad:
            diverged = t
            break
    return yh, S, diverged


def _tables(structure: fr.Structure, terms_per_output: Sequence[Sequence[tuple[int, ...]]]):
    """Flat arrays of the regressors (kind 0 = y / 1 = u, channel, lag) and of all terms of all outputs."""
    regs = structure.regressors
    if any(k == "e" for k, _, _ in regs):
        raise ConfigError("narx-poly-sim: noise (e) regressors cannot be simulated")
    kind = np.array([0 if k == "y" else 1 for k, _, _ in regs], dtype=np.int64)
    ch = np.array([c for _, c, _ in regs], dtype=np.int64)
    lag = np.array([lg for _, _, lg in regs], dtype=np.int64)
    flat = [(o, t) for o, ts in enumerate(terms_per_output) for t in ts]
    d_max = max([len(t) for _, t in flat] + [1])
    fac = -np.ones((max(len(flat), 1), d_max), dtype=np.int64)
    for i, (_, t) in enumerate(flat):
        fac[i, : len(t)] = t
    out_of = np.array([o for o, _ in flat] or [0], dtype=np.int64)
    return kind, ch, lag, fac[: len(flat)], out_of[: len(flat)]


def simulate_sensitivity(
    structure: fr.Structure,
    terms_per_output,
    theta: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    bound: float = np.inf,
    jacobian: bool = True,
) -> tuple[np.ndarray, np.ndarray, int]:
    """Free run of a polynomial NARX (first ``max_lag`` samples from ``y``) and its sensitivity to the stacked
    parameters ``theta`` (all outputs' terms in order): returns (ŷ (N, n_out), S (N, n_out, P), divergence
    index or -1). ``S`` is (1, n_out, P) zeros when ``jacobian`` is False."""
    kind, ch, lag, fac, out_of = _tables(structure, terms_per_output)
    u2 = np.ascontiguousarray(np.asarray(u, dtype=float).reshape(len(u), -1))
    y2 = np.ascontiguousarray(np.asarray(y, dtype=float).reshape(len(y), -1))
    return _sim_sens(
        y2,
        u2,
        kind,
        ch,
        lag,
        fac,
        out_of,
        np.ascontiguousarray(theta, dtype=float),
        int(structure.max_lag),
        float(bound),
        bool(jacobian),
    )


class NARXPolySim(NARXPoly):
    """Polynomial NARX: FROLS structure and least-squares start (as ``narx-poly``), then all parameters refined
    on the free-run error by Levenberg–Marquardt with the exact sensitivity Jacobian.

    Parameters
    ----------
    ny, nu, nk, degree, criterion, rho_p, max_terms, constant, chunk, monomials_of :
        As :class:`sysid.polynomial.NARXPoly` (structure selection and starting point).
    max_nfev : int
        Most simulations in the refinement (0: no refinement, the model is ``narx-poly``'s).
    xtol, ftol : float
        Relative step / cost tolerances of the refinement (scipy's ``least_squares``).
    """

    name = "narx-poly-sim"

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
        max_nfev: int = 100,
        xtol: float = 1e-10,
        ftol: float = 1e-10,
        monomials_of: str = "yu",
    ):
        super().__init__(
            ny=ny,
            nu=nu,
            nk=nk,
            degree=degree,
            criterion=criterion,
            rho_p=rho_p,
            max_terms=max_terms,
            constant=constant,
            chunk=chunk,
            monomials_of=monomials_of,
        )
        self.max_nfev = max_nfev
        self.xtol = xtol
        self.ftol = ftol

    def _fit_records(self, records: list[Record]) -> None:
        if not isinstance(self.max_nfev, (int, np.integer)) or isinstance(self.max_nfev, bool) or self.max_nfev < 0:
            raise ConfigError(f"{self.name}: max_nfev={self.max_nfev!r} must be a non-negative integer")
        for key in ("xtol", "ftol"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v < 1):
                raise ConfigError(f"{self.name}: {key}={v!r} must lie in (0, 1)")
        super()._fit_records(records)
        self.theta_ls_ = [np.asarray(t, dtype=float).copy() for t in self.theta_]
        self.refine_info_ = {"nfev": 0, "status": "not run", "rms_ls": None, "rms_sim": None}
        if self.max_nfev > 0 and any(len(t) > 0 for t in self.terms_):
            self._refine(records)

    def _refine(self, records: list[Record]) -> None:
        from scipy.optimize import least_squares

        s = self.structure_
        terms = self.terms_
        sizes = [len(t) for t in terms]
        theta0 = np.concatenate([np.asarray(t, dtype=float) for t in self.theta_])
        ys = [r.output.reshape(len(r), -1) for r in records]
        us = [r.u.reshape(len(r), -1) for r in records]
        y_all = np.concatenate(ys)
        scale = np.where(y_all.std(axis=0) > 0, y_all.std(axis=0), 1.0)
        bound = DIVERGENCE_FACTOR * max(float(np.max(np.abs(y_all))), 1e-300)
        L = s.max_lag
        cache: dict[str, Any] = {}

        def run(theta: np.ndarray, n: int | None = None) -> tuple[np.ndarray, np.ndarray, int]:
            """Scaled residuals, Jacobian and first divergence index (-1: none) over each record's first n samples."""
            key = (theta.tobytes(), n)
            if cache.get("key") != key:
                res, jac, first = [], [], -1
                for u, y in zip(us, ys):
                    u, y = u[:n], y[:n]
                    if y.shape[0] <= L:
                        continue
                    yh, S, div = simulate_sensitivity(s, terms, theta, u, y, bound, True)
                    r = (yh[L:] - y[L:]) / scale
                    J = S[L:] / scale[None, :, None]
                    if div >= 0:
                        r[div - L :] = DIVERGED_RESIDUAL
                        J[div - L :] = 0.0
                        first = div if first < 0 else min(first, div)
                    res.append(r.reshape(-1))
                    jac.append(J.reshape(-1, theta.size))
                cache.update(key=key, r=np.concatenate(res), J=np.concatenate(jac), div=first)
            return cache["r"], cache["J"], cache["div"]

        def solve(theta: np.ndarray, n: int | None):
            return least_squares(
                lambda th: run(th, n)[0],
                theta,
                jac=lambda th: run(th, n)[1],
                method="lm",
                x_scale="jac",
                max_nfev=int(self.max_nfev),
                xtol=float(self.xtol),
                ftol=float(self.ftol),
            )

        r0, _, div0 = run(theta0)
        # Continuation when the least-squares start diverges in simulation: refine on each record's first n samples,
        # n = the divergence index, then doubling, so that every stage starts from a model that is bounded on most
        # of its data (a diverged simulation has no useful gradient); never fewer residuals than parameters.
        theta, nfev, stages = theta0, 0, []
        n_max = max(len(y) for y in ys)
        n = None if div0 < 0 else max(div0, L + 50, L + theta0.size + 1)
        while n is not None and n < n_max:
            sol = solve(theta, n)
            theta, nfev = sol.x, nfev + int(sol.nfev)
            stages.append(int(n))
            n = 2 * n
        sol = solve(theta, None)
        theta, nfev = sol.x, nfev + int(sol.nfev)
        r1, J, _ = run(theta)
        rms0, rms1 = float(np.sqrt(np.mean(r0**2))), float(np.sqrt(np.mean(r1**2)))
        status = sol.message
        if not np.isfinite(rms1) or rms1 > rms0:  # never return something worse than the start
            theta, rms1, status = theta0, rms0, f"kept the least-squares start ({sol.message})"
            r1, J, _ = run(theta)
        self.refine_info_ = {
            "nfev": nfev,
            "status": str(status),
            "rms_ls": rms0,
            "rms_sim": rms1,
            "continuation_lengths": stages,
            "start_diverged_at": int(div0),
        }
        # standard errors: r and J are both divided by the output SD, so σ̂² (JᵀJ)⁻¹ is in θ's own units
        try:
            cov = np.linalg.inv(J.T @ J) * float(np.mean(r1**2))
            se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        except np.linalg.LinAlgError:
            se = np.full(theta.size, np.nan)
        offs = np.cumsum([0, *sizes])
        self.theta_ = [theta[a:b].copy() for a, b in zip(offs[:-1], offs[1:])]
        self.stderr_ = [se[a:b].copy() for a, b in zip(offs[:-1], offs[1:])]

    # ------------------------------------------------------------------ persistence / description
    def describe(self) -> dict[str, Any]:
        d = super().describe()
        if hasattr(self, "refine_info_"):
            d["refinement"] = dict(self.refine_info_)
        return d

    def _extra_state(self) -> dict[str, Any]:
        return {
            "theta_ls": [np.asarray(t).tolist() for t in getattr(self, "theta_ls_", [])],
            "refine_info": getattr(self, "refine_info_", {}),
        }

    def _load_extra(self, extra: dict[str, Any]) -> None:
        self.theta_ls_ = [np.asarray(t, dtype=float) for t in extra.get("theta_ls", [])]
        self.refine_info_ = dict(extra.get("refine_info", {}))
