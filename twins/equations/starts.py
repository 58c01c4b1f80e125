"""Starting values of a mechanism's parameters from the equation residual, before its least-squares fit.

A mechanism adds a term θ·φ(x, u) to one rate (Coulomb friction: −fc·sign(v) to v̇), linear in its size θ for a
given shape (a Stribeck velocity, a clearance, a Bouc–Wen loop shape). Along the model's own trajectory x̂(t) the
output's response to a small added term εφ(x̂(t)) is its sensitivity column S = (ŷ(εφ) − ŷ)/ε, one simulation with
the term injected as a forcing (:mod:`.kernel`); the sizes then solve the linear least-squares problem
r ≈ Σ θ_l S_l on the estimation residual r (Gauss–Newton's first step from θ = 0). Each shape of a small grid over
the shape parameters gets its own solve; the best linearised fit is the start. This replaces the diagnosis's
generic pre-scan for these effects (:func:`twins.discrepancy.trials.run_trial` asks the twin first): 1–49
simulations instead of 50–300 (Ljung, "System identification", 2nd ed., §10.2, the Gauss–Newton direction).
A mechanism that changes the trajectory's shape itself (a bound, an input mechanism) returns None: the
pre-scan searches it.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit

from sysid.data.record import Record
from twins.paramfields import param_info

from .model import MechanismSlot

__all__ = ["start_values", "best_start", "spread_starts", "direct_start", "GRID"]

#: points of the grid over each shape parameter
GRID = 7


@njit(cache=True)
def _bouc_wen_state(xdot: np.ndarray, dt: float, b1: float, b2: float, sub: int) -> np.ndarray:
    """z along a velocity history (explicit Euler, ``sub`` steps per sample)."""
    z = np.empty(xdot.size)
    zk, h = 0.0, dt / sub
    for k in range(xdot.size):
        z[k] = zk
        for _ in range(sub):
            zk += h * (xdot[k] - b1 * abs(xdot[k]) * zk - b2 * xdot[k] * abs(zk))
    return z


@njit(cache=True)
def _play_mean(x: np.ndarray, r: float, n_play: int) -> np.ndarray:
    """Mean output of ``n_play`` play operators of thresholds r·(q + ½)/n_play along ``x``, each starting at 0."""
    out = np.empty(x.size)
    p = np.zeros(n_play)
    for k in range(x.size):
        total = 0.0
        for q in range(n_play):
            rq = r * (q + 0.5) / n_play
            if x[k] - p[q] > rq:
                p[q] = x[k] - rq
            elif x[k] - p[q] < -rq:
                p[q] = x[k] + rq
            total += p[q]
        out[k] = total / n_play
    return out


def _grid(lo: float, hi: float, n: int = GRID) -> np.ndarray:
    if lo > 0 and hi / lo > 30:
        return np.geomspace(lo, hi, n)
    if lo < 0 < hi:  # symmetric: denser near 0 (loop shapes of either sign, small ones likeliest)
        m = max(abs(lo), abs(hi))
        half = m * np.geomspace(1e-2, 1.0, (n - 1) // 2)
        return np.clip(np.concatenate([-half[::-1], [0.0], half]), lo, hi)
    return np.linspace(lo, hi, n)


def _bases(
    slot: MechanismSlot, X: np.ndarray, fs: float, shape: dict[str, float]
) -> list[tuple[str, np.ndarray, float]]:
    """(key, basis φ, sign of the term) of each size parameter of ``slot`` for the shape values ``shape``."""
    kind, i = slot.mech.kind, slot.acts
    x = X[:, i]
    sgn = np.sign(x)
    if kind == "coulomb":
        return [("fc", sgn, -1.0)]
    if kind == "stribeck":
        return [("fc", sgn, -1.0), ("fs", np.exp(-((x / shape["vs"]) ** 2)) * sgn, -1.0)]
    if kind == "asymmetric_coulomb":
        return [("f_pos", (x > 0).astype(float), -1.0), ("f_neg", (x < 0).astype(float), 1.0)]
    if kind == "quadratic_damping":
        return [("c2", x * np.abs(x), -1.0)]
    if kind == "cubic_damping":
        return [("c3", x**3, -1.0)]
    if kind == "cubic_spring":
        return [("k3", x**3, -1.0)]
    if kind == "quadratic_spring":
        return [("k2", x**2, -1.0)]
    if kind == "clearance_spring":
        return [("kc", sgn * np.maximum(np.abs(x) - shape["gap"], 0.0), -1.0)]
    if kind == "bouc_wen":
        xdot = np.gradient(x) * fs
        return [("kappa", _bouc_wen_state(xdot, 1.0 / fs, shape["b1"], shape["b2"], 8), -1.0)]
    if kind == "prandtl_ishlinskii":
        return [("w", _play_mean(np.ascontiguousarray(x), shape["r"], 4), -1.0)]
    if kind == "leak":
        return [("c", x, -1.0)]
    if kind == "orifice_leak":
        return [("c", np.sqrt(np.maximum(x, 0.0)), -1.0)]
    if kind == "power_outflow":
        return [("c", np.where(x > 0.0, np.maximum(x, 0.0) ** shape["beta"], 0.0), -1.0)]
    return []


#: the shape parameters of each kind (the others are sizes, solved linearly)
SHAPES: dict[str, tuple[str, ...]] = {
    "stribeck": ("vs",),
    "clearance_spring": ("gap",),
    "bouc_wen": ("b1", "b2"),
    "prandtl_ishlinskii": ("r",),
    "power_outflow": ("beta",),
}
#: kinds whose term also acts as a linear stiffness: their sizes are solved beside a stiffness column (a nuisance)
_STIFFENING = ("bouc_wen", "prandtl_ishlinskii", "cubic_spring", "quadratic_spring", "clearance_spring")
_STIFFNESS = "_stiffness"
_LINEAR_KINDS = set(SHAPES) | {
    "coulomb",
    "asymmetric_coulomb",
    "quadratic_damping",
    "cubic_damping",
    "cubic_spring",
    "quadratic_spring",
    "leak",
    "orifice_leak",
}


def direct_start(
    slot: MechanismSlot,
    params: Any,
    y0: np.ndarray,
    rec: Record,
    skip: int,
    run: Callable[[dict[str, Any]], np.ndarray],
) -> dict[str, float] | None:
    """The start of a mechanism that reshapes the trajectory (a bound, an input mechanism): each point of a grid
    over its parameters simulated with it on (``run(values)``), the best by estimation SSE (7–21 simulations); a
    static input polynomial by its two sensitivity columns (its sizes are linear)."""
    info = param_info(type(params))
    rng = {k: info[f].bounds() for k, f in slot.fields.items()}
    y = np.asarray(rec.output, float)
    kind = slot.mech.kind
    if kind == "input_polynomial":
        u = np.asarray(rec.u, float)
        cols = []
        for key, phi in (("a2", u**2), ("a3", u**3)):
            eps = 1e-4 * max(abs(v) for v in rng[key])
            cols.append((run({"_u": u + eps * phi}) - y0)[skip:] / eps)
        A = np.column_stack(cols)
        if not np.all(np.isfinite(A)):
            return None
        theta = np.linalg.lstsq(A, (y - y0)[skip:], rcond=None)[0]
        return {slot.fields[k]: float(np.clip(t, *rng[k])) for k, t in zip(("a2", "a3"), theta)}
    grids = {k: (np.linspace(*rng[k], 3) if k == "share" else np.linspace(*rng[k], GRID)) for k in slot.fields}
    best: tuple[float, dict[str, float]] | None = None
    for combo in itertools.product(*grids.values()):
        vals = {slot.fields[k]: float(v) for k, v in zip(grids, combo)}
        yh = run(vals)
        cost = float(np.sum((y - yh)[skip:] ** 2))
        if math.isfinite(cost) and (best is None or cost < best[0]):
            best = (cost, vals)
    return None if best is None else best[1]


def best_start(found: list[tuple[float, dict[str, float]]]) -> dict[str, float] | None:
    """The start of the shape whose linearised fit is best (:func:`start_values`' list), or None."""
    return min(found, key=lambda t: t[0])[1] if found else None


def spread_starts(found: list[tuple[float, dict[str, float]]], keep: int = 3) -> list[dict[str, float]]:
    """Starts spread over the shape grid (:func:`start_values`' list, in the grid's order): the grid's points cut
    into ``keep`` runs of neighbours, the best linearised start of each run, best first. A term refitted with the
    core is refitted from shapes apart, not only from the one its linearisation picks: the calibrated core has
    taken up part of the term (a steeper outflow beside the model's Torricelli outflow raises its coefficient), and
    the residual it leaves favours the shapes the core can trade against."""
    runs = [r for r in np.array_split(np.arange(len(found)), keep) if r.size]
    picked = [min((found[i] for i in run), key=lambda t: t[0]) for run in runs]
    return [vals for _, vals in sorted(picked, key=lambda t: t[0])]


def start_values(
    slot: MechanismSlot,
    params: Any,
    X: np.ndarray,
    y0: np.ndarray,
    rec: Record,
    skip: int,
    sensitivities: Callable[[np.ndarray, np.ndarray], np.ndarray],
) -> list[tuple[float, dict[str, float]]]:
    """(linearised estimation cost, start) of ``slot``'s parameters for every shape of the grid, in the grid's order
    (module docstring; :func:`best_start`, :func:`spread_starts`): ``X``/``y0`` the model's states and output on
    ``rec`` without it, ``sensitivities(phi, rows)`` the output's sensitivity to each column of ``phi`` added to the
    rate of state ``rows[c]`` (:mod:`.tangent`)."""
    kind = slot.mech.kind
    if kind not in _LINEAR_KINDS:
        return []
    info = param_info(type(params))
    rng = {k: info[f].bounds() for k, f in slot.fields.items()}
    r = (np.asarray(rec.output, float) - y0)[skip:]
    shapes = SHAPES.get(kind, ())
    points = [
        dict(zip(shapes, (float(v) for v in combo))) for combo in itertools.product(*[_grid(*rng[k]) for k in shapes])
    ]
    cols: list[np.ndarray] = []
    where: list[tuple[int, str, float]] = []  # (grid point, size parameter, sign of the term)
    for g, shape in enumerate(points):
        for key, phi, sign in _bases(slot, X, rec.fs, shape):
            if np.max(np.abs(phi)) > 0 and np.all(np.isfinite(phi)):
                cols.append(sign * phi)
                where.append((g, key, sign))
    if not cols:
        return []
    if kind in _STIFFENING:  # the term adds stiffness too, which the calibrated core has already taken up
        cols.append(-X[:, slot.acts])
        where.append((-1, _STIFFNESS, -1.0))
    if kind == "power_outflow":  # the calibrated core has taken up part of it in its own outflow (orifice, leak)
        for j, law in enumerate((np.sqrt(np.maximum(X[:, slot.acts], 0.0)), X[:, slot.acts])):
            cols.append(-law)
            where.append((-1, f"{_STIFFNESS}{j}", -1.0))
    S = sensitivities(np.column_stack(cols), np.full(len(cols), slot.enters))[skip:]
    nuisance = [c for c, w in enumerate(where) if w[0] < 0 and np.all(np.isfinite(S[:, c]))]
    found: list[tuple[float, dict[str, float]]] = []
    for g, shape in enumerate(points):
        idx = [c for c, w in enumerate(where) if w[0] == g and np.all(np.isfinite(S[:, c])) and np.any(S[:, c] != 0)]
        if not idx:
            continue
        A = S[:, idx + nuisance]
        keys = [where[c][1] for c in idx]
        theta = np.linalg.lstsq(A, r, rcond=None)[0]
        theta[: len(keys)] = [np.clip(t, *rng[k]) for t, k in zip(theta, keys)]
        with np.errstate(over="ignore", invalid="ignore"):  # a size far off the range: an inf cost, skipped
            cost = float(np.sum((r - A @ theta) ** 2))
        theta = theta[: len(keys)]
        if math.isfinite(cost):
            found.append((cost, {**shape, **dict(zip(keys, theta.tolist()))}))
    return [(cost, {f: float(vals.get(k, getattr(params, f))) for k, f in slot.fields.items()}) for cost, vals in found]
