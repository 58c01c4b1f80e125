"""Simulation of a polynomial nonlinear state-space (PNLSS) model and its exact parameter Jacobian.

Model (Paduart et al., "Identification of nonlinear systems using polynomial nonlinear state space models",
Automatica 46 (2010) 647-656, eq. 3)::

    x(t+1) = A x(t) + B u(t) + E ζ(x(t), u(t))
    y(t)   = C x(t) + D u(t) + F η(x(t), u(t))

ζ and η stack every monomial of the n + m variables z = [x; u] of total degree 2 … d (the "full" monomial set of
the paper, §3.1), optionally after the constant 1 (an affine model: offsets of measured data); each is held as a
row of factor indices into z (``-1`` pads), so ζ_k = Π_j z[fac_k,j] (an empty product is 1).

The Jacobian of the simulated output with respect to the parameters follows from the forward sensitivity
recursion of the paper's §4.2 (eq. 18-20): with S(t) = ∂x(t)/∂θ_s (n × P_s) for the state-equation parameters
θ_s = [vec A, vec B, vec E, x(0)],

    S(t+1) = (A + E ∂ζ/∂x(t)) S(t) + ∂f/∂θ_s |direct,      S(0) = [0 … 0 | I],
    ∂y(t)/∂θ_s = (C + F ∂η/∂x(t)) S(t),                     ∂y(t)/∂θ_o = direct (x, u, η),

θ_o = [vec C, vec D, vec F] (row-major ``vec``; "direct" holds x_j, u_j, ζ_k or η_k at the entry of the
parameter). The recursion is compiled with numba; it costs O(N n² P_s).
"""

from __future__ import annotations

from itertools import combinations_with_replacement

import numpy as np
from numba import njit

__all__ = ["monomials", "monomial_names", "simulate", "n_state_params", "n_output_params"]


def monomials(n_vars: int, degree: int, constant: bool = False) -> np.ndarray:
    """Factor-index table of every monomial of ``n_vars`` variables of total degree 2 … ``degree`` (graded
    lexicographic order), after the constant 1 (a row of ``-1`` only) when ``constant``: shape (count,
    max(degree, 1)), ``-1`` pads. Degree < 2 and no constant gives an empty table."""
    rows: list[tuple[int, ...]] = [()] if constant else []
    rows += [c for d in range(2, int(degree) + 1) for c in combinations_with_replacement(range(n_vars), d)]
    fac = -np.ones((len(rows), max(int(degree), 1)), dtype=np.int64)
    for i, c in enumerate(rows):
        fac[i, : len(c)] = c
    return fac


def monomial_names(fac: np.ndarray, n: int, m: int) -> list[str]:
    """Readable names of the monomials of ``fac`` over z = [x1 … xn, u1 … um] (e.g. ``x1^2*u1``)."""
    var = [f"x{i + 1}" for i in range(n)] + (["u"] if m == 1 else [f"u{j + 1}" for j in range(m)])
    out = []
    for row in fac:
        idx = [int(r) for r in row if r >= 0]
        out.append(
            "*".join(f"{var[v]}^{idx.count(v)}" if idx.count(v) > 1 else var[v] for v in sorted(set(idx))) or "1"
        )
    return out


def n_state_params(n: int, m: int, n_zeta: int) -> int:
    """Size of θ_s without x(0): vec A, vec B, vec E."""
    return n * (n + m + n_zeta)


def n_output_params(n: int, m: int, p: int, n_eta: int) -> int:
    """Size of θ_o: vec C, vec D, vec F."""
    return p * (n + m + n_eta)


@njit(cache=True)
def _monos(z, fac, val, dval, n):  # pragma: no cover - compiled
    """Monomial values val[k] = Π z[fac[k]] and their derivatives dval[k, r] with respect to the states r < n."""
    K, d = fac.shape
    for k in range(K):
        v = 1.0
        for j in range(d):
            r = fac[k, j]
            if r < 0:
                break
            v *= z[r]
        val[k] = v
        for r in range(n):
            dval[k, r] = 0.0
        for j in range(d):
            r = fac[k, j]
            if r < 0:
                break
            if r >= n:
                continue
            g = 1.0
            for jj in range(d):
                rr = fac[k, jj]
                if rr < 0:
                    break
                if jj != j:
                    g *= z[rr]
            dval[k, r] += g


@njit(cache=True)
def _sim(A, B, C, D, E, F, facE, facF, u, x0, bound, want_jac):  # pragma: no cover - compiled
    N, m = u.shape
    n = A.shape[0]
    p = C.shape[0]
    nE = facE.shape[0]
    nF = facF.shape[0]
    Ps = n * (n + m + nE) + n  # state parameters and x(0)
    Po = p * (n + m + nF)
    P = Ps + Po
    y = np.empty((N, p))
    J = np.zeros((N if want_jac else 1, p, P))
    x = x0.copy()
    z = np.empty(n + m)
    zeta = np.empty(nE)
    dzeta = np.empty((nE, n))
    eta = np.empty(nF)
    deta = np.empty((nF, n))
    S = np.zeros((n, Ps))
    Sn = np.zeros((n, Ps))
    M = np.empty((n, n))
    G = np.empty((p, n))
    for i in range(n):
        S[i, Ps - n + i] = 1.0
    offB, offE = n * n, n * n + n * m
    offD, offF = Ps + p * n, Ps + p * n + p * m
    diverged = -1
    for t in range(N):
        for i in range(n):
            z[i] = x[i]
        for j in range(m):
            z[n + j] = u[t, j]
        _monos(z, facE, zeta, dzeta, n)
        _monos(z, facF, eta, deta, n)
        bad = False
        for o in range(p):
            acc = 0.0
            for i in range(n):
                acc += C[o, i] * x[i]
            for j in range(m):
                acc += D[o, j] * u[t, j]
            for k in range(nF):
                acc += F[o, k] * eta[k]
            y[t, o] = acc
            if not np.isfinite(acc) or abs(acc) > bound:
                bad = True
        if bad:
            diverged = t
            break
        if want_jac:
            for o in range(p):
                for i in range(n):
                    g = C[o, i]
                    for k in range(nF):
                        g += F[o, k] * deta[k, i]
                    G[o, i] = g
            for o in range(p):
                for q in range(Ps):
                    acc = 0.0
                    for i in range(n):
                        acc += G[o, i] * S[i, q]
                    J[t, o, q] = acc
                for i in range(n):
                    J[t, o, Ps + o * n + i] = x[i]
                for j in range(m):
                    J[t, o, offD + o * m + j] = u[t, j]
                for k in range(nF):
                    J[t, o, offF + o * nF + k] = eta[k]
            for i in range(n):
                for r in range(n):
                    g = A[i, r]
                    for k in range(nE):
                        g += E[i, k] * dzeta[k, r]
                    M[i, r] = g
            for i in range(n):
                for q in range(Ps):
                    acc = 0.0
                    for r in range(n):
                        acc += M[i, r] * S[r, q]
                    Sn[i, q] = acc
                for r in range(n):
                    Sn[i, i * n + r] += x[r]
                for j in range(m):
                    Sn[i, offB + i * m + j] += u[t, j]
                for k in range(nE):
                    Sn[i, offE + i * nE + k] += zeta[k]
            for i in range(n):
                for q in range(Ps):
                    S[i, q] = Sn[i, q]
        xn = np.empty(n)
        for i in range(n):
            acc = 0.0
            for r in range(n):
                acc += A[i, r] * x[r]
            for j in range(m):
                acc += B[i, j] * u[t, j]
            for k in range(nE):
                acc += E[i, k] * zeta[k]
            xn[i] = acc
        for i in range(n):
            if not np.isfinite(xn[i]) or abs(xn[i]) > bound:
                bad = True
            x[i] = xn[i]
        if bad:
            diverged = t + 1 if t + 1 < N else -1
            if diverged >= 0:
                break
    if diverged >= 0:
        for t in range(diverged, N):
            for o in range(p):
                y[t, o] = np.nan
    return y, J, diverged, x


def simulate(
    A, B, C, D, E, F, facE, facF, u, x0=None, bound: float = np.inf, jacobian: bool = False, final_state: bool = False
):
    """Free run of the PNLSS model from x(0) = ``x0`` (zeros) on input ``u`` (N, m).

    Returns (y (N, p), J, diverged): J is ∂y/∂θ (N, p, P) over θ = [vec A, vec B, vec E, x(0), vec C, vec D,
    vec F] when ``jacobian`` (else a (1, p, P) zero array); from the first sample where an output or a state
    leaves ±``bound`` (or is not finite) on, y is nan and ``diverged`` is that index (-1: none). With
    ``final_state`` the state after the last sample is returned fourth (a run continued from it is the same
    arithmetic as one run: the per-sample stepper of an FMU uses this).
    """
    mats = [np.ascontiguousarray(np.asarray(M, dtype=float)) for M in (A, B, C, D, E, F)]
    n = mats[0].shape[0]
    u2 = np.ascontiguousarray(np.asarray(u, dtype=float).reshape(len(u), -1))
    x = np.zeros(n) if x0 is None else np.ascontiguousarray(np.asarray(x0, dtype=float).reshape(n))
    out = _sim(
        *mats,
        np.ascontiguousarray(facE),
        np.ascontiguousarray(facF),
        u2,
        x,
        float(bound),  # type: ignore[call-arg]
        bool(jacobian),
    )
    return out if final_state else out[:3]
