"""Records with a mechanism hidden inside the equations, made by test code of its own (not by the catalog's laws or
the project's integrator): a mass-spring-damper with Coulomb friction, a cubic spring, Bouc-Wen hysteresis or a
position-dependent damping (outside the catalog), and two cascaded tanks whose upper tank overflows.

Each case is a function of the seed: the excitation, the noise and the mechanism's size are drawn from it. The
simulator is a fixed-step RK4 with 16 steps per sample and the input interpolated linearly (the tanks: held), in
plain numpy; the models the diagnosis gets are the textbook ones, written as a user would (:data:`MSD_MODEL`,
:data:`TANKS_MODEL`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy import signal

from sysid.data.record import Record

FS_MSD = 1000.0  # Hz
F0_HZ, ZETA, GAIN = 40.0, 0.05, 1.0
N_MSD = 4000
NOISE = 0.003  # measurement noise, share of the output's standard deviation

MSD_MODEL = '''"""A mass-spring-damper as a user writes it first."""
import math
from dataclasses import dataclass

from twins.base import pfield

NAME = "msd"
STATES = {"x": ("position", "m"), "v": ("velocity", "m/s")}
INPUT = "linear"


@dataclass
class Params:
    f0_hz: float = pfield(42.0, "Hz", 5.0, 200.0, "resonance frequency")
    zeta: float = pfield(0.06, "1", 0.001, 1.0, "damping ratio")
    gain: float = pfield(1.0, "m/N", 0.01, 100.0, "static gain")


def rates(x, u, p):
    w = 2.0 * math.pi * p.f0_hz
    return (x[1], w * w * (p.gain * u - x[0]) - 2.0 * p.zeta * w * x[1])


def output(x, u, p):
    return x[0]
'''

TANKS_MODEL = '''"""Two cascaded tanks by Torricelli's law, as a user writes them first."""
import math
from dataclasses import dataclass

from twins.base import pfield

NAME = "tanks"
STATES = {"x1": ("level", "cm"), "x2": ("level", "cm")}


@dataclass
class Params:
    k1: float = pfield(0.1, "cm^0.5/s", 0.005, 2.0, "outflow of the upper tank")
    k2: float = pfield(0.1, "cm^0.5/s", 0.005, 2.0, "inflow of the lower tank")
    k3: float = pfield(0.1, "cm^0.5/s", 0.005, 2.0, "outflow of the lower tank")
    k4: float = pfield(0.1, "cm/(V s)", 0.005, 2.0, "pump gain")


def rates(x, u, p):
    q1 = math.sqrt(max(x[0], 0.0))
    return (p.k4 * u - p.k1 * q1, p.k2 * q1 - p.k3 * math.sqrt(max(x[1], 0.0)))


def output(x, u, p):
    return x[1]
'''


def excitation(n: int, fs: float, rng: np.random.Generator, band: tuple[float, float], amp: float) -> np.ndarray:
    """Gaussian noise band-limited to ``band`` [Hz], scaled to the standard deviation ``amp``."""
    sos = signal.butter(4, band, btype="band", fs=fs, output="sos")
    u = signal.sosfilt(sos, rng.standard_normal(n + 500))[500:]
    return amp * u / np.std(u)


def rk4(f: Callable, x0: list[float], u: np.ndarray, fs: float, sub: int = 16, hold: bool = False) -> np.ndarray:
    """States at every sample: y[k] is the state at t_k, then RK4 over [t_k, t_k+1] in ``sub`` steps."""
    x = np.array(x0, float)
    out = np.empty((u.size, x.size))
    h = 1.0 / (fs * sub)
    for k in range(u.size):
        out[k] = x
        u0 = u[k]
        u1 = u0 if hold or k + 1 >= u.size else u[k + 1]
        for s in range(sub):
            ua, um, ub = (u0 + (u1 - u0) * (s + c) / sub for c in (0.0, 0.5, 1.0))
            k1 = f(x, ua)
            k2 = f(x + 0.5 * h * k1, um)
            k3 = f(x + 0.5 * h * k2, um)
            k4 = f(x + h * k3, ub)
            x = x + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6.0
    return out


def _msd(extra: Callable[[np.ndarray], float], n_extra: int = 0, zdot: Callable | None = None) -> Callable:
    w = 2 * math.pi * F0_HZ

    def f(x: np.ndarray, u: float) -> np.ndarray:
        a = w * w * (GAIN * u - x[0]) - 2 * ZETA * w * x[1] - extra(x)
        out = [x[1], a]
        if zdot is not None:
            out.append(zdot(x))
        return np.array(out)

    return f


def _linear_scale() -> tuple[float, float]:
    """Standard deviations of the linear oscillator's position and velocity for the excitation used."""
    rng = np.random.default_rng(12345)
    u = excitation(N_MSD, FS_MSD, rng, (2.0, 150.0), 1.0)
    X = rk4(_msd(lambda x: 0.0), [0.0, 0.0], u, FS_MSD, sub=4)
    return float(np.std(X[:, 0])), float(np.std(X[:, 1]))


def msd_case(kind: str, seed: int) -> tuple[Record, Record, dict[str, float]]:
    """Estimation and validation records of the oscillator with the mechanism ``kind`` hidden (``none``,
    ``coulomb``, ``cubic``, ``bouc_wen``, ``outside``), and the hidden parameters by the catalog's key."""
    rng = np.random.default_rng(seed)
    sx, sv = _linear_scale()
    w = 2 * math.pi * F0_HZ
    truth: dict[str, float] = {}
    zdot = None
    if kind == "none":

        def extra(x: np.ndarray) -> float:
            return 0.0
    elif kind == "coulomb":
        truth["fc"] = fc = float(rng.uniform(0.05, 0.15)) * w * w * sx

        def extra(x: np.ndarray) -> float:
            return fc * float(np.sign(x[1]))
    elif kind == "cubic":
        truth["k3"] = k3 = float(rng.uniform(0.05, 0.15)) * w * w / sx**2

        def extra(x: np.ndarray) -> float:
            return k3 * x[0] ** 3
    elif kind == "bouc_wen":
        truth["kappa"] = kappa = float(rng.uniform(0.3, 0.6)) * w * w
        truth["b1"] = b1 = float(rng.uniform(0.5, 1.5)) / sx
        truth["b2"] = b2 = float(rng.uniform(-1.0, 0.5)) / sx

        def extra(x: np.ndarray) -> float:
            return kappa * x[2]

        def zdot(x: np.ndarray) -> float:
            return x[1] - b1 * abs(x[1]) * x[2] - b2 * x[1] * abs(x[2])
    elif kind == "outside":  # a damping that grows with the displacement (van der Pol): no catalog entry has it
        truth["c"] = c = float(rng.uniform(1.0, 2.0)) * w / sx**2

        def extra(x: np.ndarray) -> float:
            return c * x[0] ** 2 * x[1]
    else:
        raise ValueError(kind)
    f = _msd(extra, zdot=zdot)
    x0 = [0.0, 0.0, 0.0] if zdot is not None else [0.0, 0.0]
    recs = []
    for part in range(2):
        u = excitation(N_MSD, FS_MSD, rng, (2.0, 150.0), 1.0)
        y = rk4(f, x0, u, FS_MSD)[:, 0]
        y = y + NOISE * np.std(y) * rng.standard_normal(y.size)
        recs.append(Record(u=u, y=y, fs=FS_MSD, units={"u": "N", "y": "m"}, source=f"msd-{kind}-{seed}-{part}"))
    return recs[0], recs[1], truth


FS_TANKS = 0.25  # Hz
N_TANKS = 1200
TANKS_TRUE = {"k1": 0.1, "k2": 0.09, "k3": 0.08, "k4": 0.15}


def tanks_case(seed: int, hidden: str = "overflow") -> tuple[Record, Record, dict[str, float]]:
    """Estimation and validation records of two cascaded tanks whose upper tank overflows at a level drawn from
    the seed, half of the spill reaching the lower tank (``level``, ``share``: the spill per unit of the cut
    inflow, in the lower tank's rate); ``hidden="power_outflow"``: no overflow, the lower tank drained beside its
    orifice by a weir-like outflow c·x₂^β (β 1.1–1.4; at 10 cm 20–40 % of the orifice's flow)."""
    rng = np.random.default_rng(seed if hidden == "overflow" else 1000 + seed)
    k1, k2, k3, k4 = (TANKS_TRUE[k] for k in ("k1", "k2", "k3", "k4"))
    if hidden == "overflow":
        level = float(rng.uniform(8.0, 12.0))
        share = 0.5 * k2 / k1  # half of the spill, in the lower tank's units
        beta = c_out = 0.0
    else:
        level, share = math.inf, 0.0
        beta = float(rng.uniform(1.1, 1.4))
        c_out = float(rng.uniform(0.05, 0.1)) / 10.0**beta

    def f(x: np.ndarray, u: float) -> np.ndarray:
        q1 = math.sqrt(max(x[0], 0.0))
        d1 = k4 * u - k1 * q1
        d2 = k2 * q1 - k3 * math.sqrt(max(x[1], 0.0)) - (c_out * x[1] ** beta if x[1] > 0 else 0.0)
        if x[0] >= level and d1 > 0:
            d2 += share * d1
            d1 = 0.0
        return np.array([d1, d2])

    recs = []
    for part in range(2):
        # pump steps held for 40-200 s, reaching over the overflow level now and then
        u = np.empty(N_TANKS)
        k = 0
        while k < N_TANKS:
            d = int(rng.integers(10, 50))
            u[k : k + d] = rng.uniform(0.5, 3.0)
            k += d
        x = np.zeros(2)
        X = np.empty((N_TANKS, 2))
        h = 1.0 / (FS_TANKS * 16)
        for i in range(N_TANKS):
            X[i] = x
            for _ in range(16):
                a = f(x, u[i])
                b = f(x + 0.5 * h * a, u[i])
                c = f(x + 0.5 * h * b, u[i])
                e = f(x + h * c, u[i])
                x = x + h * (a + 2 * b + 2 * c + e) / 6.0
                x[0] = min(x[0], level)
        y = X[:, 1] + 0.02 * rng.standard_normal(N_TANKS)
        recs.append(Record(u=u, y=y, fs=FS_TANKS, units={"u": "V", "y": "cm"}, source=f"tanks-{seed}-{part}"))
    if hidden == "overflow":
        return recs[0], recs[1], {"level": level, "share": share}
    return recs[0], recs[1], {"c": c_out, "beta": beta}
