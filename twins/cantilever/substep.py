"""Integration sub-step of the cantilever twin chosen from the record.

Inside one sample interval the kernel (:mod:`.kernels`) is exact for everything except one approximation:
the force f = Γ[v] + creep is taken as piecewise linear between the M sub-step nodes (first-order hold into
the exactly discretised D(s)·sensor). The command v is linear in time inside the sample (FOH of the input),
so over a sub-step the voltage changes by δ = |Δu|/M and the FOH error of f is the interpolation error of
Γ(v) over δ:

    |e_f| ≤ κ·δ²/8,     κ = max |d²Γ/dv²| = α·d·(β + |γ|)·(1 + rate-scale)    (Bouc–Wen, n = 1)

from dh/dv = αd − (β·sgn v̇ ± γ)·h ⇒ |d²h/dv²| ≤ (β + |γ|)·αd. The Bouc–Wen state itself is integrated in
closed form (no error accumulates in h) and the creep chain per sample, so the error is a transient of the
linear part; its peak in y is at most |e_f|·A with A = max(1, max_k |H(j2πk/h)|) the largest gain of
D(s)·sensor at the sub-step rate and its first harmonics (the error is periodic in sub-steps).

``choose_substep(twin, u, fs, tol)`` returns the coarsest sub-step whose bound stays below
``tol``·(d·span of u), never coarser than one sample and never finer than the twin's own ``max_substep_s``
(the default 20 µs is kept where the record needs it). The bandwidth of the record enters through max|Δu|
(a slow record at 1 kHz changes little per sample); the modes kept enter through A. For the
Prandtl–Ishlinskii operator (piecewise-linear Γ, first-order FOH error at play corners) the twin's own
setting is returned unchanged. The test suite checks the bound against the 1 µs solution.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["choose_substep", "DEFAULT_TOL"]

#: default error budget: peak FOH error ≤ DEFAULT_TOL × (d · span of u), 10⁻⁴ as the fit-time 50 µs step
DEFAULT_TOL = 1e-4


def choose_substep(twin, u: np.ndarray, fs: float, tol: float = DEFAULT_TOL) -> float:
    """Largest ``max_substep_s`` [s] for which the FOH error bound of the module docstring is ≤ ``tol``·d·span."""
    p = twin.params
    own = float(p.max_substep_s)
    u = np.asarray(u, float).ravel()
    T = 1.0 / float(fs)
    if p.hysteresis != "bouc-wen" or u.size < 2:
        return own
    span = float(np.max(u) - np.min(u))
    if not span > 0:
        return max(own, T)
    lim = float(p.amp_limit_v)
    du = float(np.max(np.abs(np.diff(np.clip(u, -lim, lim)))))
    alpha = min(float(p.bw_alpha) * (2.0 if twin.has("rate_dependent_hysteresis") else 1.0), 0.98)
    if twin.has("asymmetric_hysteresis"):
        alpha = min(alpha * (1.0 + abs(float(p.asym_factor))), 0.98)
    d = abs(float(p.gain_um_per_v))
    kappa = alpha * d * (abs(float(p.bw_beta)) + abs(float(p.bw_gamma)))
    budget = tol * d * span
    best = own
    M = 1
    while M <= 4096:
        h = T / M
        if h <= own:
            break
        delta = du / M
        amp = _gain_at(twin, h)
        if kappa * delta * delta / 8.0 * amp <= budget:
            best = max(h, own)
            break
        M = int(math.ceil(M * 1.25)) if M > 4 else M + 1
    return float(min(best, 1e-3))  # the parameter's documented range ends at 1 ms


def _gain_at(twin, h: float) -> float:
    """max(1, |H| at the sub-step rate 1/h and its harmonics 2/h, 3/h), H = D(s)·sensor normalised."""
    f = np.array([1.0, 2.0, 3.0]) / h
    try:
        g = np.abs(twin.frequency_response(f))
    except (AttributeError, np.linalg.LinAlgError):
        return 1.0
    return float(max(1.0, np.max(g)))
