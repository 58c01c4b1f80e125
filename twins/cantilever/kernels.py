"""Compiled simulation kernel of the cantilever twin (numba) and its exact discretisation.

One kernel, :func:`run_block`, advances the whole chain sample by sample and keeps every state in arrays
passed in, so that :meth:`CantileverTwin.simulate` (one call over the whole input) and the stepper of
:meth:`CantileverTwin.make_stepper` (one call per sample) execute exactly the same arithmetic.

Per sample interval [t_{k−1}, t_k] (T = 1/fs), split into M sub-steps of h = T/M:

1. input delay: u_d[k] = u((k − τ·fs)·T) by linear interpolation of the sample sequence (zeros before t = 0);
2. amplifier: soft saturation c = u_d/(1 + |u_d/V_s|^p)^(1/p) (effect ``saturation``), hard clip at ±amp_limit;
   first-order low-pass (effect ``amplifier_bandwidth``) integrated exactly for the first-order-hold (FOH)
   command inside the interval → v at the sub-step nodes;
3. hysteresis Γ at every sub-step node: Bouc–Wen (Low & Guo, n = 1) integrated *exactly* for the piecewise
   linear v (the rate-independent ODE dh/dv = αd − βs·h − γ|h| is linear in v between sign changes of h) or
   the Prandtl–Ishlinskii sum of play operators (exact for piecewise-monotone input);
4. creep: Kelvin–Voigt chain Σ g_i d/(τ_i s + 1) on v, discretised exactly per sample (FOH), linearly
   interpolated at the sub-step nodes;
5. force f = Γ + creep into the 6-state linear system (two modes of D(s) and the 2nd-order sensor low-pass),
   discretised exactly with a FOH on f per sub-step (matrix exponential, :func:`foh_discretise`);
6. output y_k = C z + offset + drift + σ·n_k, quantised to q; the drift is D·(1 − e^(−t/τ)) (thermal_drift)
   + r·t + a·sin(ωt) + b·(1 − cos ωt) (slow_drift) at t = k·T (zero at t = 0: no offset of its own).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "expm_small",
    "foh_discretise",
    "run_block",
    "pi_play",
    "pi_inverse_weights",
    "I_M",
    "I_DELAY",
    "I_HYST",
    "I_NPI",
    "I_NCR",
    "I_SAT",
    "I_AMPLP",
    "I_RATE",
    "I_ASYM",
    "I_DRIFT",
    "I_QUANT",
    "N_ICFG",
    "F_T",
    "F_H",
    "F_MU",
    "F_VS",
    "F_SATP",
    "F_LIM",
    "F_LPA",
    "F_LPB0",
    "F_LPB1",
    "F_D",
    "F_ALPHA",
    "F_BETA",
    "F_GAMMA",
    "F_RATEREF",
    "F_ASYM",
    "F_OFFSET",
    "F_DRIFT",
    "F_DRIFTTAU",
    "F_Q",
    "F_RATEA",
    "F_DRATE",
    "F_DSIN",
    "F_DCOS",
    "F_DOMEGA",
    "N_FCFG",
    "S_CPREV",
    "S_VPREV",
    "S_H",
    "S_FPREV",
    "S_K",
    "S_BUFI",
    "S_CRPREV",
    "S_RHO",
    "N_SCAL",
    "NZ",
]

# integer configuration indices
I_M, I_DELAY, I_HYST, I_NPI, I_NCR, I_SAT, I_AMPLP, I_RATE, I_ASYM, I_DRIFT, I_QUANT = range(11)
N_ICFG = 11
# float configuration indices
(
    F_T,
    F_H,
    F_MU,
    F_VS,
    F_SATP,
    F_LIM,
    F_LPA,
    F_LPB0,
    F_LPB1,
    F_D,
    F_ALPHA,
    F_BETA,
    F_GAMMA,
    F_RATEREF,
    F_ASYM,
    F_OFFSET,
    F_DRIFT,
    F_DRIFTTAU,
    F_Q,
    F_RATEA,
    F_DRATE,
    F_DSIN,
    F_DCOS,
    F_DOMEGA,
) = range(24)
N_FCFG = 24
# scalar state indices
S_CPREV, S_VPREV, S_H, S_FPREV, S_K, S_BUFI, S_CRPREV, S_RHO = range(8)
N_SCAL = 8
#: states of the linear part: mode 1 (x, ẋ), mode 2 (x, ẋ), sensor (s, ṡ)
NZ = 6


@njit(cache=True)
def _matmul(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """X @ Y by explicit loops: the same sums on every CPU (no BLAS kernel chosen at run time)."""
    n, m, p = X.shape[0], X.shape[1], Y.shape[1]
    out = np.zeros((n, p))
    for i in range(n):
        for k in range(m):
            x = X[i, k]
            if x != 0.0:
                for j in range(p):
                    out[i, j] += x * Y[k, j]
    return out


@njit(cache=True)
def _expm_balanced(A: np.ndarray) -> np.ndarray:
    n = A.shape[0]
    d = np.ones(n)
    for _ in range(20):  # diagonal balancing by powers of 2 (Parlett & Reinsch): exact in floating point
        changed = False
        for i in range(n):
            c = 0.0
            r = 0.0
            for j in range(n):
                if j != i:
                    c += abs(A[j, i])
                    r += abs(A[i, j])
            if c > 0 and r > 0:
                f = 2.0 ** np.rint(0.5 * math.log2(r / c))
                if f != 1.0:
                    A[:, i] *= f
                    A[i, :] /= f
                    d[i] *= f
                    changed = True
        if not changed:
            break
    norm = 0.0
    for j in range(n):
        col = 0.0
        for i in range(n):
            col += abs(A[i, j])
        norm = max(norm, col)
    s = max(0, int(math.ceil(math.log2(norm / 0.25)))) if norm > 0.25 else 0
    X = A / (2.0**s)
    E = np.eye(n)
    term = np.eye(n)
    for k in range(1, 19):
        term = _matmul(term, X) / k
        E = E + term
    for _ in range(s):
        E = _matmul(E, E)
    for i in range(n):
        for j in range(n):
            E[i, j] = E[i, j] * d[i] / d[j]
    return E


def expm_small(A: np.ndarray) -> np.ndarray:
    """Matrix exponential of a small matrix by scaling and squaring with a Taylor series (compiled by numba).

    The argument is balanced by powers of 2, scaled by 2^-s so that its 1-norm is ≤ 1/4, the series is summed to
    18 terms (truncation < 1e-24 relative), then squared s times (Moler & Van Loan 2003, "Nineteen dubious ways",
    method 3). Used instead of ``scipy.linalg.expm`` for the 8 × 8 FOH matrix: SciPy's threaded LAPACK is two
    orders of magnitude slower per call on a loaded machine (docs/diagnosis.md); the tests check both agree to
    1e-12. Compiled with explicit loops (0.33 ms → 0.009 ms per call; a diagnosis discretises thousands of systems).
    """
    A = np.array(A, dtype=np.float64, order="C")  # a copy: the balancing scales it in place
    if A.size == 0:
        return np.eye(A.shape[0])
    return _expm_balanced(A)


def foh_discretise(A: np.ndarray, B: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact discretisation of ẋ = Ax + Bf for an input f that is linear between the nodes (first-order hold).

    Returns (Φ, G0, G1) with x_{n+1} = Φ x_n + G0 f_n + G1 f_{n+1}. Uses the augmented system
    [ẋ; ḟ; ẇ] = [[A, B, 0], [0, 0, 1/h], [0, 0, 0]]·[x; f; w] with w = f_{n+1} − f_n (Franklin & Powell,
    "Digital Control of Dynamic Systems", §6.3).
    """
    n = A.shape[0]
    Maug = np.zeros((n + 2, n + 2))
    Maug[:n, :n] = A
    Maug[:n, n] = B
    Maug[n, n + 1] = 1.0 / h
    E = expm_small(Maug * h)
    Phi = E[:n, :n].copy()
    g_u = E[:n, n].copy()  # response to f_n held
    g_w = E[:n, n + 1].copy()  # response to the ramp w
    return Phi, g_u - g_w, g_w


@njit(cache=True, inline="always")
def _evolve(h0, a, k, w):
    """Solution of dh/dv = a − k·h after a step w in v (exact, linear ODE in v)."""
    kw = k * w
    if abs(kw) < 1e-10:
        return h0 + (a - k * h0) * w
    return h0 - (a / k - h0) * math.expm1(-kw)


@njit(cache=True)
def _bouc_wen(h, w, a, beta, gamma):
    """Exact Bouc–Wen (n = 1) update of h for a linear change w of the input (Low & Guo form).

    ḣ = a·v̇ − β|v̇|h − γ v̇|h| with a = αd; dividing by v̇ (constant sign s inside the step):
    dh/dv = a − (βs + γ)h for h ≥ 0 and a − (βs − γ)h for h < 0, solved in closed form with one switch of
    region where h crosses zero (at dh/dv = a > 0, so h crosses upward for w > 0, downward for w < 0).
    """
    if w == 0.0:
        return h
    s = 1.0 if w > 0.0 else -1.0
    pos = h > 0.0 or (h == 0.0 and w > 0.0)
    k = beta * s + (gamma if pos else -gamma)
    hn = _evolve(h, a, k, w)
    if (pos and hn < 0.0) or ((not pos) and hn > 0.0):
        # find the input change ws where h reaches zero: h0 + (a/k − h0)(1 − e^{−k ws}) = 0
        if abs(k * h / a) < 1e-12:
            ws = -h / a
        else:
            arg = -k * h / a
            if arg <= -1.0:
                return hn
            ws = math.log1p(arg) / k
        k2 = beta * s + (-gamma if pos else gamma)
        hn = _evolve(0.0, a, k2, w - ws)
    return hn


@njit(cache=True)
def run_block(
    u, noise, out, icfg, fcfg, sc, z, xc, play, buf, vsub, Phi, G0, G1, Cout, cr_a, cr_b0, cr_b1, cr_g, pi_r, pi_p
):
    """Advance the twin over the samples ``u`` (V) writing ``out`` (µm); all state arrays are updated in place.

    ``noise`` holds σ·n_k per sample (zeros when measurement noise is off). ``sc`` holds the scalar states
    (S_* indices), ``z`` the linear states, ``xc`` the creep elements, ``play`` the PI play outputs, ``buf`` the
    delay line and ``vsub`` is scratch of length M + 1.
    """
    M = icfg[I_M]
    D = icfg[I_DELAY]
    hyst = icfg[I_HYST]
    npi = icfg[I_NPI]
    ncr = icfg[I_NCR]
    sat_on = icfg[I_SAT] != 0
    lp_on = icfg[I_AMPLP] != 0
    rate_on = icfg[I_RATE] != 0
    asym_on = icfg[I_ASYM] != 0
    drift_on = icfg[I_DRIFT] != 0
    quant_on = icfg[I_QUANT] != 0
    T = fcfg[F_T]
    hsub = fcfg[F_H]
    mu = fcfg[F_MU]
    Vs = fcfg[F_VS]
    satp = fcfg[F_SATP]
    lim = fcfg[F_LIM]
    lpa = fcfg[F_LPA]
    lpb0 = fcfg[F_LPB0]
    lpb1 = fcfg[F_LPB1]
    d = fcfg[F_D]
    alpha = fcfg[F_ALPHA]
    beta = fcfg[F_BETA]
    gamma = fcfg[F_GAMMA]
    rate_ref = fcfg[F_RATEREF]
    asym = fcfg[F_ASYM]
    offset = fcfg[F_OFFSET]
    drift = fcfg[F_DRIFT]
    drift_tau = fcfg[F_DRIFTTAU]
    d_rate = fcfg[F_DRATE]
    d_sin = fcfg[F_DSIN]
    d_cos = fcfg[F_DCOS]
    d_omega = fcfg[F_DOMEGA]
    q = fcfg[F_Q]
    rate_a = fcfg[F_RATEA]
    pi_psum = 0.0
    for i in range(npi):
        pi_psum += pi_p[i + 1]
    pi_cmax = 1.0 + 0.95 * pi_p[0] / pi_psum if pi_psum > 0.0 else 1.0
    rho = sc[S_RHO]
    L = buf.shape[0]
    nz = z.shape[0]
    zn = np.empty(nz)  # the linear part has NZ = 6 states (see module docstring)
    invM = 1.0 / M

    for k in range(u.shape[0]):
        # ---- 1. delay line (linear interpolation between stored samples)
        bi = int(sc[S_BUFI])
        buf[bi] = u[k]
        if D == 0 and mu == 0.0:
            ud = u[k]
        else:
            i0 = (bi - D) % L
            i1 = (bi - D - 1) % L
            ud = (1.0 - mu) * buf[i0] + mu * buf[i1]
        sc[S_BUFI] = (bi + 1) % L
        # ---- 2. amplifier
        c1 = ud
        if sat_on:
            c1 = c1 / (1.0 + abs(c1 / Vs) ** satp) ** (1.0 / satp)
        if c1 > lim:
            c1 = lim
        elif c1 < -lim:
            c1 = -lim
        c0 = sc[S_CPREV]
        vsub[0] = sc[S_VPREV]
        for m in range(1, M + 1):
            cm = c0 + (c1 - c0) * (m * invM)
            if lp_on:
                cprev = c0 + (c1 - c0) * ((m - 1) * invM)
                vsub[m] = lpa * vsub[m - 1] + lpb0 * cprev + lpb1 * cm
            else:
                vsub[m] = cm
        # ---- 4. creep (per sample, exact FOH), output interpolated inside the interval
        cr0 = sc[S_CRPREV]
        cr1 = 0.0
        v0 = vsub[0]
        v1 = vsub[M]
        for i in range(ncr):
            xc[i] = cr_a[i] * xc[i] + cr_g[i] * d * (cr_b0[i] * v0 + cr_b1[i] * v1)
            cr1 += xc[i]
        # ---- 3 + 5. hysteresis and linear dynamics per sub-step
        h = sc[S_H]
        f0 = sc[S_FPREV]
        for m in range(1, M + 1):
            va = vsub[m - 1]
            vb = vsub[m]
            w = vb - va
            vmid = 0.5 * (va + vb)
            scale = 1.0
            if rate_on:  # rate envelope ρ: first-order low-pass of |v̇|, exact for the constant rate in the sub-step
                rho = rate_a * rho + (1.0 - rate_a) * abs(w) / hsub
                scale = 1.0 + rho / rate_ref
            ascale = 1.0
            if asym_on and vmid < 0.0:
                ascale = 1.0 + asym * (-vmid) / lim
            if hyst == 0:
                aeff = alpha * scale * ascale
                if aeff > 0.98:  # keep the initial slope d(1 − α) after a reversal positive
                    aeff = 0.98
                h = _bouc_wen(h, w, aeff * d, beta, gamma)
                gam = d * vb - h
            else:
                # rate/asymmetry move weight from the linear operator to the plays (the slope d of large
                # loops is kept, the loop widens), like α in Bouc–Wen; p_0 stays ≥ 5 % of its value
                c = scale * ascale
                if c > pi_cmax:
                    c = pi_cmax
                acc_play = 0.0
                for i in range(npi):
                    r = pi_r[i]
                    fp = play[i]
                    lo = vb - r
                    hi = vb + r
                    if fp < lo:
                        fp = lo
                    elif fp > hi:
                        fp = hi
                    play[i] = fp
                    acc_play += pi_p[i + 1] * fp
                gam = (pi_p[0] - (c - 1.0) * pi_psum) * vb + c * acc_play
            f1 = gam + cr0 + (cr1 - cr0) * (m * invM)
            # Φ is block lower-triangular: modes 1 and 2 are uncoupled 2×2 blocks, the sensor sees both
            z0, z1, z2, z3, z4, z5 = z[0], z[1], z[2], z[3], z[4], z[5]
            z[0] = Phi[0, 0] * z0 + Phi[0, 1] * z1 + G0[0] * f0 + G1[0] * f1
            z[1] = Phi[1, 0] * z0 + Phi[1, 1] * z1 + G0[1] * f0 + G1[1] * f1
            z[2] = Phi[2, 2] * z2 + Phi[2, 3] * z3 + G0[2] * f0 + G1[2] * f1
            z[3] = Phi[3, 2] * z2 + Phi[3, 3] * z3 + G0[3] * f0 + G1[3] * f1
            for i in range(4, 6):
                zn[i] = (
                    Phi[i, 0] * z0
                    + Phi[i, 1] * z1
                    + Phi[i, 2] * z2
                    + Phi[i, 3] * z3
                    + Phi[i, 4] * z4
                    + Phi[i, 5] * z5
                    + G0[i] * f0
                    + G1[i] * f1
                )
            z[4] = zn[4]
            z[5] = zn[5]
            f0 = f1
        sc[S_H] = h
        sc[S_RHO] = rho
        sc[S_FPREV] = f0
        sc[S_CPREV] = c1
        sc[S_VPREV] = vsub[M]
        sc[S_CRPREV] = cr1
        # ---- 6. sensor output
        y = offset + noise[k]
        for i in range(nz):
            y += Cout[i] * z[i]
        if drift_on:
            tk = sc[S_K] * T
            y += (
                drift * (-math.expm1(-tk / drift_tau))
                + d_rate * tk
                + d_sin * math.sin(d_omega * tk)
                + d_cos * (1.0 - math.cos(d_omega * tk))
            )
        if quant_on:
            y = q * math.floor(y / q + 0.5)
        out[k] = y
        sc[S_K] += 1.0


@njit(cache=True)
def pi_play(v, r, p0, p):
    """Prandtl–Ishlinskii operator y = p0·v + Σ p_i F_{r_i}[v] on samples ``v`` (plays start at rest, notes A.4)."""
    n = r.shape[0]
    state = np.zeros(n)
    for i in range(n):  # F_r(t0) = max(v0 − r, min(v0 + r, 0))
        state[i] = max(v[0] - r[i], min(v[0] + r[i], 0.0))
    y = np.empty(v.shape[0])
    for k in range(v.shape[0]):
        acc = p0 * v[k]
        for i in range(n):
            fp = state[i]
            lo = v[k] - r[i]
            hi = v[k] + r[i]
            if fp < lo:
                fp = lo
            elif fp > hi:
                fp = hi
            state[i] = fp
            acc += p[i] * fp
        y[k] = acc
    return y


def pi_inverse_weights(r: np.ndarray, p0: float, p: np.ndarray) -> tuple[np.ndarray, float, np.ndarray]:
    """Analytic inverse of a PI operator (Kuhnen & Janocha 2001; physics notes A.4).

    With thresholds 0 = r_0 < r_1 < … < r_n and weights p_0, p_1 … p_n the inverse is again a PI operator:
    r'_i = Σ_{j≤i} p_j (r_i − r_j), p'_0 = 1/p_0, p'_i = −p_i / ((p_0 + Σ_{j=1}^{i} p_j)(p_0 + Σ_{j=1}^{i−1} p_j)).
    Returns (r', p'_0, p') for use with :func:`pi_play`.
    """
    r = np.asarray(r, dtype=float)
    p = np.asarray(p, dtype=float)
    rr = np.concatenate(([0.0], r))
    pp = np.concatenate(([p0], p))
    if p0 <= 0 or np.any(np.cumsum(pp) <= 0):
        raise ValueError("PI inverse needs p_0 > 0 and positive partial sums p_0 + Σ p_j")
    r_inv = np.array([np.sum(pp[: i + 1] * (rr[i] - rr[: i + 1])) for i in range(1, rr.size)])
    cs = np.cumsum(pp)
    p_inv = np.array([-pp[i] / (cs[i] * cs[i - 1]) for i in range(1, rr.size)])
    return r_inv, 1.0 / p0, p_inv
