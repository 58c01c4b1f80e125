"""Small nonlinear test plants for the neural identifiers (used until/besides the twins).

``bouc_wen_record``: a second-order oscillator driven through a Bouc–Wen hysteresis operator, the
structure of the cantilever twin (physics notes A.1) at a smaller scale:
    m x'' + c x' + k x = k (d u − h),   h' = A d u' − β |u'| |h|^(n−1) h − γ u' |h|^n   (n = 1)
integrated with RK4 sub-steps on a linearly interpolated input; output y = x (plus optional noise).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from sysid.data.record import Record


def multisine_input(n: int, fs: float, f_max: float, seed: int, amplitude: float = 1.0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    freqs = np.linspace(fs / n * 4, f_max, 40)
    u = np.sum(np.sin(2 * np.pi * freqs[:, None] * t[None, :] + rng.uniform(0, 2 * np.pi, (freqs.size, 1))), axis=0)
    return amplitude * u / np.max(np.abs(u))


def sine_input(n: int, fs: float, f: float, amplitude: float = 1.0) -> np.ndarray:
    return amplitude * np.sin(2 * np.pi * f * np.arange(n) / fs)


@njit(cache=True)
def _bw_kernel(u, fs, w0, zeta, d, A, beta, gamma, substeps):
    dt = 1.0 / fs / substeps
    x = 0.0
    v = 0.0
    h = 0.0
    y = np.zeros(u.size)
    for i in range(u.size):
        y[i] = x
        if i + 1 == u.size:
            break
        u0 = u[i]
        du = (u[i + 1] - u0) * fs
        for j in range(substeps):
            s0 = np.array([x, v, h])
            ks = np.zeros((4, 3))
            for st in range(4):
                c = 0.0 if st == 0 else (0.5 if st < 3 else 1.0)
                tt = (j + c) / substeps
                uu = u0 + du / fs * tt
                if st == 0:
                    s = s0
                else:
                    s = s0 + dt * c * ks[st - 1]
                hh = s[2]
                ks[st, 0] = s[1]
                ks[st, 1] = -2 * zeta * w0 * s[1] - w0 * w0 * s[0] + w0 * w0 * (d * uu - hh)
                ks[st, 2] = A * d * du - beta * abs(du) * abs(hh) * hh - gamma * du * hh * abs(hh)
            s1 = s0 + dt / 6 * (ks[0] + 2 * ks[1] + 2 * ks[2] + ks[3])
            x, v, h = s1[0], s1[1], s1[2]
    return y


def bouc_wen_record(
    u: np.ndarray,
    fs: float = 1000.0,
    f0: float = 40.0,
    zeta: float = 0.1,
    d: float = 1.0,
    A: float = 1.0,
    beta: float = 0.6,
    gamma: float = 0.3,
    noise: float = 0.0,
    seed: int = 0,
    substeps: int = 8,
) -> Record:
    y = _bw_kernel(
        np.ascontiguousarray(u, dtype=float), float(fs), 2 * np.pi * f0, zeta, d, A, beta, gamma, int(substeps)
    )
    if noise:
        y = y + noise * np.std(y) * np.random.default_rng(seed).standard_normal(y.size)
    return Record(u=u, y=y, fs=fs, units={"u": "V", "y": "m"}, meta={"system": "bouc-wen test plant"})
