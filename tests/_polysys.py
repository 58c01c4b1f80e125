"""Known polynomial systems shared by the identification tests (simulated here, not by the code under test)."""

import numpy as np

from sysid.data.record import Record

# y(k) = 0.2 y(k-1) + 0.1 y(k-1) u(k-1) + 0.9 u(k-2) - 0.3 u(k-1)^2   (names as sysid prints them)
TRUE_TERMS = {"y(k-1)": 0.2, "y(k-1)*u(k-1)": 0.1, "u(k-2)": 0.9, "u(k-1)^2": -0.3}


def narx_record(n=1500, seed=0, lead_zeros=0, noise=0.0):
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, n)
    u[:lead_zeros] = 0.0
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 0.2 * y[k - 1] + 0.1 * y[k - 1] * u[k - 1] + 0.9 * u[k - 2] - 0.3 * u[k - 1] ** 2
    y = y + noise * rng.standard_normal(n)
    return Record(u, y, fs=1.0, source=f"narx-seed{seed}")


def narmax_record(n=3000, seed=3, c1=0.8, sigma=0.05):
    """Polynomial NARMAX with an MA(1) noise term: coloured equation error."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, n)
    e = sigma * rng.standard_normal(n)
    y = np.zeros(n)
    for k in range(2, n):
        y[k] = 0.5 * y[k - 1] + u[k - 1] - 0.3 * u[k - 1] ** 2 + 0.1 * y[k - 1] * u[k - 1] + c1 * e[k - 1] + e[k]
    return Record(u, y, fs=1.0, source=f"narmax-seed{seed}")


def table(model, output=None):
    return {r["term"]: r["parameter"] for r in model.term_table() if output is None or r.get("output", 0) == output}


def duffing(u: np.ndarray, fs: float = 2.0, substeps: int = 10) -> np.ndarray:
    """ÿ + 0.4 ẏ + y + 2 y³ = u (a Duffing oscillator: the nonlinearity acts on the state it measures; resonance
    near 0.16 Hz, sampled at 2 Hz as Silverbox's 60 Hz at 610 Hz), RK4 with the input held over each sample."""

    def f(s, uk):
        return np.array([s[1], uk - 0.4 * s[1] - s[0] - 2.0 * s[0] ** 3])

    h, s, y = 1.0 / (fs * substeps), np.zeros(2), np.zeros(u.size)
    for k, uk in enumerate(u):
        y[k] = s[0]
        for _ in range(substeps):
            k1 = f(s, uk)
            k2 = f(s + 0.5 * h * k1, uk)
            k3 = f(s + 0.5 * h * k2, uk)
            s = s + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + f(s + h * k3, uk))
    return y
