"""The laws of the mechanisms the diagnosis can add inside a model's equations, as compiled functions.

Each law is a small numba function of floats, callable from Python and from a model's compiled ``rates``: the
integrator (:mod:`.kernel`) evaluates them, and a model written back by ``diagnose --save-model``
(:mod:`.writer`) calls them by name, so the extended file reads as physics (``dv -= laws.coulomb(v, fc)``).
Signs: a friction or restoring law returns the force per unit of the rate it enters (it is subtracted).

References: Olsson, Åström, Canudas de Wit, Gäfvert & Lischinsky, "Friction models and friction compensation"
(Eur. J. Control 1998), eqs. (2)–(6) for Coulomb and Stribeck friction; Kovacic & Brennan, "The Duffing
equation" (2011), ch. 1 for the cubic and quadratic restoring forces; Ismail, Ikhouane & Rodellar, "The
hysteresis Bouc–Wen model, a survey" (Arch. Comput. Methods Eng. 2009), eq. (3) with n = 1; Brokate & Sprekels,
"Hysteresis and phase transitions" (1996), §2.3 for the play operator and the Prandtl–Ishlinskii sum.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "sgn",
    "coulomb",
    "stribeck",
    "asymmetric_coulomb",
    "quadratic_damping",
    "cubic_damping",
    "cubic_spring",
    "quadratic_spring",
    "clearance_spring",
    "bouc_wen_rate",
    "play_rate",
    "power_outflow",
    "dead_zone",
    "input_polynomial",
    "backlash",
]


@njit(cache=True)
def sgn(v: float) -> float:
    """The sign of ``v`` (0 at 0)."""
    return 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)


@njit(cache=True)
def coulomb(v: float, fc: float) -> float:
    """Coulomb friction ``fc·sign(v)`` on a velocity ``v``."""
    return fc * sgn(v)


@njit(cache=True)
def stribeck(v: float, fc: float, fs_excess: float, vs: float) -> float:
    """Stribeck friction ``(fc + fs_excess·exp(−(v/vs)²))·sign(v)``: static friction fc + fs_excess at rest,
    falling to the Coulomb level fc over the Stribeck velocity vs."""
    return (fc + fs_excess * math.exp(-((v / vs) ** 2))) * sgn(v)


@njit(cache=True)
def asymmetric_coulomb(v: float, f_pos: float, f_neg: float) -> float:
    """Coulomb friction of different sizes in the two directions: ``f_pos`` for v > 0, ``−f_neg`` for v < 0."""
    return f_pos if v > 0.0 else (-f_neg if v < 0.0 else 0.0)


@njit(cache=True)
def quadratic_damping(v: float, c2: float) -> float:
    """Quadratic (turbulent, drag) damping ``c2·v·|v|``."""
    return c2 * v * abs(v)


@njit(cache=True)
def cubic_damping(v: float, c3: float) -> float:
    """Cubic damping ``c3·v³``."""
    return c3 * v * v * v


@njit(cache=True)
def cubic_spring(x: float, k3: float) -> float:
    """Cubic restoring force ``k3·x³`` (k3 > 0 hardening, < 0 softening)."""
    return k3 * x * x * x


@njit(cache=True)
def quadratic_spring(x: float, k2: float) -> float:
    """Quadratic (asymmetric) restoring force ``k2·x²``."""
    return k2 * x * x


@njit(cache=True)
def clearance_spring(x: float, gap: float, kc: float) -> float:
    """A spring that engages beyond a clearance: ``kc·sign(x)·max(|x| − gap, 0)``."""
    return kc * sgn(x) * max(abs(x) - gap, 0.0)


@njit(cache=True)
def bouc_wen_rate(xdot: float, z: float, b1: float, b2: float) -> float:
    """Rate of the Bouc–Wen state z (position units, n = 1): ``ż = ẋ − b1·|ẋ|·z − b2·ẋ·|z|``; the restoring
    force is ``κ·z``. With Noël & Schoukens' benchmark form ż = αẏ − β(γ|ẏ|z + δẏ|z|): b1 = βγ, b2 = βδ."""
    return xdot - b1 * abs(xdot) * z - b2 * xdot * abs(z)


@njit(cache=True)
def play_rate(xdot: float, x: float, p: float, r: float) -> float:
    """Rate of a play operator's output p of threshold r: p follows x (rate ẋ) while x pushes it at either edge
    of the band |x − p| ≤ r, and holds still inside it."""
    if (xdot > 0.0 and x - p >= r) or (xdot < 0.0 and x - p <= -r):
        return xdot
    return 0.0


@njit(cache=True)
def power_outflow(x: float, c: float, beta: float) -> float:
    """An outflow growing as a power of the stored quantity: ``c·x^β`` for x > 0, 0 otherwise (β = ½ is
    Torricelli's orifice, β = 1 a linear, laminar leak; c < 0 takes back part of the model's own outflow)."""
    return c * x**beta if x > 0.0 else 0.0


@njit(cache=True)
def dead_zone(u: float, d: float) -> float:
    """Dead zone of half-width d: ``sign(u)·max(|u| − d, 0)``."""
    return sgn(u) * max(abs(u) - d, 0.0)


@njit(cache=True)
def input_polynomial(u: float, a2: float, a3: float) -> float:
    """A static input nonlinearity ``u + a2·u² + a3·u³``."""
    return u + a2 * u * u + a3 * u * u * u


@njit(cache=True)
def backlash(u: np.ndarray, r: float) -> np.ndarray:
    """The input samples ``u`` through a backlash (play) of half-width r, starting centred on ``u[0]``."""
    out = np.empty(u.size)
    p = u[0] if u.size else 0.0
    for k in range(u.size):
        if u[k] - p > r:
            p = u[k] - r
        elif u[k] - p < -r:
            p = u[k] + r
        out[k] = p
    return out
