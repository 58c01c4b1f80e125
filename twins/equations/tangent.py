"""Output sensitivities to added terms in the rates: the model's tangent-linear (variational) equations.

A term ε·φ(t) added to the rate of state j moves the states by δx(t), to first order in ε the solution of
δẋ = A(t)·δx + e_j·φ(t), δx(0) = 0, with A(t) = ∂f/∂x along the trajectory, and the output by
δy = ∂h/∂x·δx (forward sensitivity analysis; Hairer, Nørsett & Wanner, "Solving ordinary differential equations
I", §I.14). :func:`build_tangent` integrates the model and the variational equations of many forcings at once,
with the same RK4 steps as :mod:`.kernel` and A, ∂h/∂x by forward differences at every stage: one pass gives
every column that the starting values of a round's mechanisms (:mod:`.starts`) and the sparse term's forward
regression (:mod:`.sparse`) need, at the cost of 1 + n simulations of an n-state model.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from .kernel import N_PLAY, _input, _mech_rates

__all__ = ["build_tangent"]


def build_tangent(rates: Any, output: Any) -> Any:
    """The compiled ``tangent(p, x0, uf, dt, mech, lo, hi, phi, rows) -> (y, S)`` of one model (``uf`` as for
    :func:`.kernel.build_integrator`):
    ``phi`` (samples × C) the forcings, held over each sample, ``rows`` (C) the state whose rate each enters;
    ``S`` (samples × C) the output's sensitivity to each (module docstring)."""

    @njit(inline="always")
    def f_all(p, xa, n, u, mech, out):
        d = rates(xa[:n], u, p)
        for i in range(n):
            out[i] = d[i]
        for i in range(n, xa.size):
            out[i] = 0.0
        _mech_rates(xa, mech, out)

    @njit(cache=False)
    def tangent(p, x0, uf, dt, mech, lo, hi, phi, rows):
        n_all, N, C = x0.size, uf.shape[0], rows.size
        substeps = (uf.shape[1] - 1) // 2
        n = n_all - _added(mech)
        y = np.full(N, np.nan)
        S = np.full((N, C), np.nan)
        x = x0.copy()
        D = np.zeros((n_all, C))
        kx = np.empty((4, n_all))
        kd = np.empty((4, n_all, C))
        xs, ds = np.empty(n_all), np.empty((n_all, C))
        f0, f1, xp, g = np.empty(n_all), np.empty(n_all), np.empty(n_all), np.empty(n_all)
        A = np.empty((n_all, n_all))
        h = dt / substeps
        for k in range(N):
            uk = _input(uf[k, 0], mech)
            y[k] = output(x[:n], uk, p)
            for i in range(n):  # ∂h/∂x by forward differences
                e = 1e-7 * max(abs(x[i]), 1e-6)
                xp[:] = x
                xp[i] += e
                g[i] = (output(xp[:n], uk, p) - y[k]) / e
            for c in range(C):
                acc = 0.0
                for i in range(n):
                    acc += g[i] * D[i, c]
                S[k, c] = acc
            for s in range(substeps):
                for st in range(4):
                    c0 = 0.0 if st == 0 else (1.0 if st == 3 else 0.5)
                    prev = 2 if st == 3 else max(st - 1, 0)
                    for i in range(n_all):
                        xs[i] = x[i] + c0 * h * kx[prev, i] if st else x[i]
                        for c in range(C):
                            ds[i, c] = D[i, c] + c0 * h * kd[prev, i, c] if st else D[i, c]
                    us = _input(uf[k, 2 * s + (0 if st == 0 else (2 if st == 3 else 1))], mech)
                    f_all(p, xs, n, us, mech, f0)
                    for j in range(n_all):
                        e = 1e-7 * max(abs(xs[j]), 1e-6)
                        xp[:] = xs
                        xp[j] += e
                        f_all(p, xp, n, us, mech, f1)
                        for i in range(n_all):
                            A[i, j] = (f1[i] - f0[i]) / e
                    for i in range(n_all):
                        kx[st, i] = f0[i]
                        for c in range(C):
                            acc = 0.0
                            for j in range(n_all):
                                acc += A[i, j] * ds[j, c]
                            kd[st, i, c] = acc
                    for c in range(C):
                        kd[st, rows[c], c] += phi[k, c]
                finite = True
                for i in range(n_all):
                    x[i] = min(
                        max(x[i] + h * (kx[0, i] + 2.0 * kx[1, i] + 2.0 * kx[2, i] + kx[3, i]) / 6.0, lo[i]), hi[i]
                    )
                    finite = finite and math.isfinite(x[i])
                    for c in range(C):
                        D[i, c] += h * (kd[0, i, c] + 2.0 * kd[1, i, c] + 2.0 * kd[2, i, c] + kd[3, i, c]) / 6.0
                if not finite:
                    return y, S
        return y, S

    return tangent


@njit(cache=True)
def _added(mech: np.ndarray) -> int:
    """States the active mechanisms add (Bouc–Wen one, Prandtl–Ishlinskii N_PLAY)."""
    total = 0
    for m in range(mech.shape[0]):
        kind = int(mech[m, 0])
        if kind == 9:
            total += 1
        elif kind == 10:
            total += N_PLAY
    return total
