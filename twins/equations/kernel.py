"""The compiled integrator of a model's equations with the mechanisms the diagnosis adds inside them.

:func:`integrate` runs the classical Runge–Kutta scheme (RK4) with ``substeps`` steps per sample on the augmented
state [the model's states, the mechanisms' added states]. Sample k: ``y[k] = output(x(t_k), u_k, p)``, then the
state advances over [t_k, t_k+1] with the input held at u_k (a zero-order hold: a DAC, a pump set once per sample),
interpolated linearly to u_k+1 or on a cubic spline through the samples (a sampled smooth signal), as
:func:`stage_inputs` gives it.

Each active mechanism is one row of ``mech`` (its kind, the state it acts on, the state its term enters, the
first of its added states, then its parameters); the laws are those of :mod:`.laws`. A bounded state
(overflow) is applied last: at its bound with a rising rate, the rate is moved (times a share) into the state
it spills into, and the state is held at the bound after every step. ``sp_*`` hold a sparse term (monomials of
the states and the input, each added to one rate), ``force`` an additive input to each rate held over a sample
(the output's sensitivity to a term, :mod:`.sparse`). The model's ``rates`` and ``output`` are numba functions
(:mod:`.model` compiles them), bound into the loop by :func:`build_integrator`: one compilation per model.
Everything the loop calls is inlined at a single call site: a numba call that passes arrays costs ~100 ns
(their reference counts), more than the model's own rates (measured 3.4 → 12 ms per 65 000 samples with a call,
5.8 ms inlined).

A state that turns non-finite ends the run: the rest of ``y`` is NaN (a failed trial, never an exception).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from . import laws

__all__ = ["build_integrator", "stage_inputs", "apply_input", "KIND", "N_PLAY", "MECH_COLS"]

#: mechanism kind → code of the compiled dispatch (internal; the catalog names them, :mod:`.catalog`)
KIND = {
    "coulomb": 1,
    "stribeck": 2,
    "asymmetric_coulomb": 3,
    "quadratic_damping": 4,
    "cubic_damping": 5,
    "cubic_spring": 6,
    "quadratic_spring": 7,
    "clearance_spring": 8,
    "bouc_wen": 9,
    "prandtl_ishlinskii": 10,
    "leak": 11,
    "orifice_leak": 12,
    "overflow": 13,
    "dead_zone": 14,
    "input_polynomial": 15,
    "backlash": 16,
    "power_outflow": 17,
}
#: play operators of the Prandtl–Ishlinskii mechanism (thresholds r·(q + ½)/N_PLAY, equal weights)
N_PLAY = 4


#: columns of a row of ``mech``: kind, acts on, enters, first added state, then up to 4 parameters
MECH_COLS = 8


@njit(inline="always")
def _mech_rates(xa, mech, out):
    """Add every mechanism's term to the rates ``out`` (the model's own rates already in it)."""
    for m in range(mech.shape[0]):
        kind, i, j, e = int(mech[m, 0]), int(mech[m, 1]), int(mech[m, 2]), int(mech[m, 3])
        a, b, c = mech[m, 4], mech[m, 5], mech[m, 6]
        if kind == 1:
            out[i] -= laws.coulomb(xa[i], a)
        elif kind == 2:
            out[i] -= laws.stribeck(xa[i], a, b, c)
        elif kind == 3:
            out[i] -= laws.asymmetric_coulomb(xa[i], a, b)
        elif kind == 4:
            out[i] -= laws.quadratic_damping(xa[i], a)
        elif kind == 5:
            out[i] -= laws.cubic_damping(xa[i], a)
        elif kind == 6:
            out[j] -= laws.cubic_spring(xa[i], a)
        elif kind == 7:
            out[j] -= laws.quadratic_spring(xa[i], a)
        elif kind == 8:
            out[j] -= laws.clearance_spring(xa[i], a, b)
        elif kind == 9:
            out[e] = laws.bouc_wen_rate(out[i], xa[e], b, c)
            out[j] -= a * xa[e]
        elif kind == 10:
            total = 0.0
            for q in range(N_PLAY):
                out[e + q] = laws.play_rate(out[i], xa[i], xa[e + q], b * (q + 0.5) / N_PLAY)
                total += xa[e + q]
            out[j] -= a * total / N_PLAY
        elif kind == 11:
            out[i] -= a * xa[i]
        elif kind == 12:
            out[i] -= a * math.sqrt(max(xa[i], 0.0))
        elif kind == 17:
            out[i] -= laws.power_outflow(xa[i], a, b)
    for m in range(mech.shape[0]):  # bounds last: they move what is left of the rate
        if int(mech[m, 0]) == 13:
            i, j = int(mech[m, 1]), int(mech[m, 2])
            if xa[i] >= mech[m, 4] and out[i] > 0.0:
                if j >= 0:
                    out[j] += mech[m, 5] * out[i]
                out[i] = 0.0


@njit(inline="always")
def _input(u, mech):
    """The input as it enters the rates: the stateless input mechanisms (dead zone, polynomial) applied."""
    for m in range(mech.shape[0]):
        kind = int(mech[m, 0])
        if kind == 14:
            u = laws.dead_zone(u, mech[m, 4])
        elif kind == 15:
            u = laws.input_polynomial(u, mech[m, 4], mech[m, 5])
    return u


@njit(inline="always")
def _sparse_rates(xa, n, u, sp_exp, sp_row, sp_coef, out):
    for t in range(sp_row.size):
        term = sp_coef[t]
        for s in range(n):
            for _ in range(sp_exp[t, s]):
                term *= xa[s]
        for _ in range(sp_exp[t, n]):
            term *= u
        out[sp_row[t]] += term


def build_integrator(rates: Any, output: Any, sparse: bool = False) -> Any:
    """The compiled integrator of one model (module docstring): ``integrate(p, x0, uf, dt, mech, lo, hi, sp_exp,
    sp_row, sp_coef, force, keep) -> (y, X)``, X the states at every sample when ``keep``; ``uf`` (samples ×
    2·substeps + 1) the input at the fractions j/(2·substeps) of each sample interval (:func:`stage_inputs`).

    ``sparse``: the variant that adds the sparse term and the forcing (:mod:`.sparse`); the other ignores them,
    since their loops, even empty, make every step 2.5× slower (6.5 → 16 ms per 65 000 samples)."""

    @njit(inline="always")
    def rates_all(p, xa, n, u, mech, sp_exp, sp_row, sp_coef, force, k, out):
        d = rates(xa[:n], u, p)
        for i in range(n):
            out[i] = d[i]
        for i in range(n, xa.size):
            out[i] = 0.0
        _mech_rates(xa, mech, out)
        if sparse:
            _sparse_rates(xa, n, u, sp_exp, sp_row, sp_coef, out)
        if sparse and force.shape[0]:
            for i in range(n):
                out[i] += force[k, i]

    @njit(cache=False)
    def integrate(p, x0, uf, dt, mech, lo, hi, sp_exp, sp_row, sp_coef, force, keep):
        n_all, n, N = x0.size, sp_exp.shape[1] - 1, uf.shape[0]
        substeps = (uf.shape[1] - 1) // 2
        y = np.full(N, np.nan)
        X = np.empty((N if keep else 0, n_all))
        x = x0.copy()
        kk = np.empty((4, n_all))
        tmp = np.empty(n_all)
        h = dt / substeps
        for k in range(N):
            y[k] = output(x[:n], _input(uf[k, 0], mech), p)
            if keep:
                X[k, :] = x
            for s in range(substeps):
                for st in range(4):
                    if st == 0:
                        for i in range(n_all):
                            tmp[i] = x[i]
                    elif st == 3:
                        for i in range(n_all):
                            tmp[i] = x[i] + h * kk[2, i]
                    else:
                        for i in range(n_all):
                            tmp[i] = x[i] + 0.5 * h * kk[st - 1, i]
                    us = _input(uf[k, 2 * s + (0 if st == 0 else (2 if st == 3 else 1))], mech)
                    rates_all(p, tmp, n, us, mech, sp_exp, sp_row, sp_coef, force, k, kk[st])
                finite = True
                for i in range(n_all):
                    x[i] = x[i] + h * (kk[0, i] + 2.0 * kk[1, i] + 2.0 * kk[2, i] + kk[3, i]) / 6.0
                    x[i] = min(max(x[i], lo[i]), hi[i])
                    finite = finite and math.isfinite(x[i])
                if not finite:
                    return y, X
        return y, X

    return integrate


def stage_inputs(u: np.ndarray, substeps: int, mode: str) -> np.ndarray:
    """The input at the fractions j/(2m), j = 0 … 2m, of every sample interval (m = ``substeps``), where RK4 evaluates
    the rates: held at u_k (``hold``), linear to u_k+1 (``linear``) or on the not-a-knot cubic spline through the
    samples (``cubic``: a sampled smooth signal; on the Bouc–Wen benchmark's multisine the true model's error falls
    from 7.3·10⁻⁶ m with linear interpolation to 2.5·10⁻⁷ m). After the last sample the input is held."""
    u = np.asarray(u, dtype=np.float64)
    frac = np.arange(2 * substeps + 1) / (2.0 * substeps)
    if mode == "hold" or u.size < 2:
        return np.repeat(u[:, None], frac.size, axis=1)
    if mode == "linear":
        nxt = np.append(u[1:], u[-1])
        return u[:, None] + (nxt - u)[:, None] * frac[None, :]
    from scipy.interpolate import CubicSpline

    # the spline's cubic on each interval, evaluated at the fixed fractions by Horner's rule rather than by
    # CubicSpline.__call__, which locates every point (4.1× faster: tests/perf/test_equation_inputs.py)
    return _horner_stages(CubicSpline(np.arange(u.size, dtype=float), u).c, frac, u[-1])


@njit(cache=True)
def _horner_stages(c, frac, last):  # pragma: no cover - compiled
    n, m = c.shape[1] + 1, frac.size
    out = np.empty((n, m))
    for i in range(n - 1):
        for j in range(m):
            t = frac[j]
            out[i, j] = ((c[0, i] * t + c[1, i]) * t + c[2, i]) * t + c[3, i]
    for j in range(m):
        out[n - 1, j] = last
    return out


def apply_input(u: np.ndarray, mech: np.ndarray) -> np.ndarray:
    """The input samples through the input mechanisms with memory (backlash), before the integration."""
    out = np.asarray(u, dtype=np.float64)
    for m in range(mech.shape[0]):
        if int(mech[m, 0]) == KIND["backlash"]:
            out = laws.backlash(out, float(mech[m, 4]))
    return out
