"""What no named mechanism explains, found inside the equations: a sparse term chosen by forward regression.

When the diagnosis ends far above the noise with a model given by its equations, the remainder is looked for as
a sum of a few monomials of the states and the input, each added to one rate: dx_i/dt += θ·x₁^a₁…x_n^a_n·u^b
(total degree ≤ 3, a constant included; not in a position's rate, which is its velocity by definition). Every
candidate's effect on the output along the model's trajectory is its sensitivity column (:mod:`.tangent`);
FROLS (:func:`sysid.polynomial.frols.frols`, Billings, "Nonlinear system identification", 2013, §3.2, the error
reduction ratio of eq. 3.24) picks the terms on the estimation residual by BIC with the residual's effective
number of samples, and the terms are then fitted by simulation error (the model held) and judged on the
validation record by the diagnosis's F-test with every term counted. The term is reported by its monomials: no
physical name is claimed, so the verdict stays ``unexplained``.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.evaluation.metrics import nrmse
from sysid.polynomial.frols import frols

__all__ = ["candidate_terms", "sparse_block", "term_text", "DEGREE", "MAX_TERMS"]

#: highest total degree of a candidate monomial
DEGREE = 3
#: most terms the forward regression keeps
MAX_TERMS = 6


def candidate_terms(n_vars: int, degree: int = DEGREE) -> list[tuple[int, ...]]:
    """Exponent tuples of every monomial of ``n_vars`` variables of total degree 0 … ``degree``."""
    out = []
    for d in range(degree + 1):
        for combo in itertools.combinations_with_replacement(range(n_vars), d):
            e = [0] * n_vars
            for v in combo:
                e[v] += 1
            out.append(tuple(e))
    return out


def term_text(exps: tuple[int, ...], names: list[str]) -> str:
    """``x²·v`` for the exponents (2, 1, 0) of the variables ``x, v, u``; ``1`` for a constant."""
    sup = str.maketrans("0123456789", "⁰¹²³⁴⁵⁶⁷⁸⁹")
    parts = [n if e == 1 else f"{n}{str(e).translate(sup)}" for n, e in zip(names, exps) if e]
    return "·".join(parts) or "1"


def _columns(X: np.ndarray, u: np.ndarray, terms: list[tuple[int, ...]], scale: np.ndarray) -> np.ndarray:
    V = np.column_stack([X, u]) / scale
    return np.column_stack([np.prod(V ** np.array(e), axis=1) for e in terms])


def sparse_block(twin: Any, est: Record, val: Record, skip: int, alpha: float) -> tuple[dict[str, Any], Any]:
    """The sparse term of ``twin`` (an :class:`.twin.EquationTwin` as the diagnosis ends) on ``est``, judged on
    ``val`` (module docstring): ``(block, term)``, the block its terms, coefficients with standard errors, the
    validation NRMSE before and after and the F-test; the term ``(exponents, rates, coefficients)`` as
    :meth:`.model.EquationSpec.run` takes it (None when nothing was fitted)."""
    from scipy.optimize import least_squares

    from twins.discrepancy import features as ft
    from twins.discrepancy.prediction import continues, significance

    spec = twin.SPEC
    n = spec.n
    y0, X = twin.run(est.u, est.fs, keep=True)
    X = X[:, :n]
    u = np.asarray(est.u, float)
    r = np.asarray(est.output, float) - y0
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(X))):
        return {"fitted": False, "note": "the model's simulation is not finite"}, None
    scale = np.array([float(np.max(np.abs(c))) or 1.0 for c in np.column_stack([X, u]).T])
    terms = candidate_terms(n + 1)
    base = _columns(X, u, terms, scale)
    # a position's rate is its velocity by definition: terms go into the other rates
    free = [i for i in range(n) if not any(sl.acts == i and sl.mech.enters == "pair" for sl in spec.slots)]
    phi = np.repeat(base, len(free), axis=1)
    rows = np.tile(np.array(free), len(terms))
    S = twin.sensitivity(est, phi, rows)[skip:]
    ok = np.all(np.isfinite(S), axis=0) & (np.std(S, axis=0) > 0)
    idx = np.flatnonzero(ok)
    Sn = S[:, idx] / np.linalg.norm(S[:, idx], axis=0)
    rr = r[skip:]
    n_eff = max(ft.effective_samples(rr), 2.0 * MAX_TERMS + 2)
    A = np.column_stack([Sn, rr])
    sel = frols(A.T @ A, len(idx), n_samples=int(n_eff), criterion="bic", max_terms=MAX_TERMS).selected
    chosen = [int(idx[j]) for j in sel]
    if not chosen:
        return {"fitted": False, "note": "forward regression kept no term"}, None
    theta0 = np.linalg.lstsq(S[:, chosen], rr, rcond=None)[0]
    exps = np.array([terms[c // len(free)] for c in chosen], dtype=np.int64)
    rates = np.array([rows[c] for c in chosen], dtype=np.int64)
    to_phys = 1.0 / np.prod(scale**exps, axis=1)

    def simulate(theta: np.ndarray, rec_u: np.ndarray) -> np.ndarray:
        return twin.run(rec_u, est.fs, sparse=(exps, rates, theta * to_phys))[0]

    def resid(theta: np.ndarray) -> np.ndarray:
        e = (simulate(theta, u) - est.output)[skip:]
        return np.where(np.isfinite(e), e, 1e3 * (np.std(est.output) or 1.0))

    fit = least_squares(resid, theta0, x_scale=np.maximum(np.abs(theta0), 1e-12), max_nfev=40)
    theta = fit.x
    dof = max(len(rr) - len(theta), 1)
    cov = np.linalg.pinv(fit.jac.T @ fit.jac) * float(np.sum(fit.fun**2)) / dof
    stderr = np.sqrt(np.maximum(np.diag(cov), 0.0)) * to_phys

    def on_val(theta: np.ndarray) -> np.ndarray:
        if continues(est, val):
            return simulate(theta, np.concatenate([u, val.u]))[len(est) :]
        return simulate(theta, np.asarray(val.u, float))

    yv0, yv1 = on_val(np.zeros_like(theta)), on_val(theta)
    sse0 = float(np.sum((val.output - yv0)[skip:] ** 2))
    sse1 = float(np.sum((val.output - yv1)[skip:] ** 2)) if np.all(np.isfinite(yv1)) else math.inf
    n_eff_v = ft.effective_samples((val.output - yv1)[skip:]) if math.isfinite(sse1) else 1.0
    p = significance(sse0, sse1, n_eff_v, len(theta))
    names = spec.states + ["u"]
    rows_out = [
        {
            "rate": spec.states[int(i)],
            "term": term_text(tuple(int(v) for v in e), names),
            "coef": float(c * f),
            "stderr": float(s),
        }
        for i, e, c, f, s in zip(rates, exps, theta, to_phys, stderr)
    ]
    text = "; ".join(f"d{row['rate']}/dt += {row['coef']:.4g}·{row['term']}" for row in rows_out)
    block = {
        "fitted": True,
        "terms": rows_out,
        "text": text,
        "n_params": len(theta),
        "nrmse_val_before": nrmse(val.output, yv0, skip),
        "nrmse_val_after": nrmse(val.output, yv1, skip) if math.isfinite(sse1) else math.inf,
        "p_value": p,
        "significant": bool(p < alpha and sse1 < sse0),
    }
    return block, (exps, rates, theta * to_phys)
