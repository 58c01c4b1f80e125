"""A ladder of hand-written cascaded-tanks models: how far a physical model gets on the benchmark's test, and where
its class stops (docs/benchmarks-sota.md, "How far a richer physical model goes").

Each rung adds one piece of physics to Torricelli's two tanks (Schoukens et al. 2016, eqs. (1)–(2)):

    ẋ₁ = k₄·(u(t − τ) − u₀)₊ − q₁,   q₁ = k₁·(x₁ − c₁)₊^a₁,   ẋ₂ = g·q₁ + s·spill − k₃·(x₂ − c₂)₊^a₂,
    y = x₂ + e·q₁,

x₁ held at its overflow level h₁ (what flows in beyond it spills, the share s into the lower tank), x₂ at h₂.
Levels in the sensor's volts; u [V] is held over each 4 s sample and reaches the tank τ [s] later (the pump's
transport delay; each Euler step takes the delayed input's mean over the step, so τ acts continuously); explicit
Euler with ``substeps`` steps a sample. Every parameter of a rung and both start levels are fitted by least
squares on the free-run error over the whole estimation record from ``starts`` starts (seed fixed); the fit with
the lowest estimation error is scored on the test from its own start levels, or from levels fitted on the test's
initialisation window (4 and 50 samples, the benchmark's protocol). The last column fits the same class to the
test record itself: the best the class can do there, whatever it is fitted on.

``python -m benchmarks.tanks_ladder [--starts 16] [--substeps 8] [--json]`` prints the table (about 1 min).
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import numpy as np
from numba import njit
from scipy.optimize import least_squares

__all__ = ["NAMES", "RUNGS", "simulate", "fit", "window_start", "run"]

#: every parameter of the ladder's model, in the order :func:`simulate` takes them
NAMES = ("k1", "k3", "k4", "a1", "a2", "u0", "h1", "s", "h2", "c2", "g", "c1", "e", "tau")
#: value of a parameter a rung does not fit (a Torricelli tank, unbounded, outlets at the sensor's zero, no delay)
FIXED = dict(
    k1=0.05, k3=0.05, k4=0.03, a1=0.5, a2=0.5, u0=0.0, h1=100.0, s=0.0, h2=100.0, c2=0.0, g=1.0, c1=0.0, e=0.0, tau=0.0
)
BOUNDS = dict(
    k1=(1e-3, 1.0), k3=(1e-3, 1.0), k4=(1e-3, 1.0), a1=(0.1, 1.5), a2=(0.1, 1.5), u0=(-3.0, 3.0), h1=(5.0, 15.0),
    s=(0.0, 2.0), h2=(8.0, 12.0), c2=(-5.0, 4.5), g=(0.1, 3.0), c1=(-5.0, 4.0), e=(-20.0, 20.0),
    tau=(0.0, 16.0),
)  # fmt: skip
_CORE = ("k1", "k3", "k4", "h1", "s", "h2", "g")
#: (rung, parameters it fits besides the two start levels)
RUNGS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("Torricelli (a = ½), both tanks bounded, spill share", _CORE),
    ("+ free outflow exponents a₁, a₂", _CORE + ("a1", "a2")),
    ("+ pump dead zone u₀", _CORE + ("a1", "a2", "u0")),
    ("+ lower outlet above the sensor's zero, c₂", _CORE + ("a1", "a2", "u0", "c2")),
    ("+ upper outlet offset c₁", _CORE + ("a1", "a2", "u0", "c2", "c1")),
    ("+ pump transport delay τ", _CORE + ("a1", "a2", "u0", "c2", "c1", "tau")),
    ("+ a term of the upper outflow in the reading, e", _CORE + ("a1", "a2", "u0", "c2", "c1", "tau", "e")),
)
TS = 4.0  # s, the benchmark's sampling period


@njit(cache=True)
def simulate(u: np.ndarray, p: np.ndarray, x10: float, x20: float, substeps: int) -> np.ndarray:
    """The output y [V] of the ladder's model (module docstring) for the held input ``u`` [V], parameters ``p`` in
    :data:`NAMES`' order and start levels x10, x20 [V]."""
    k1, k3, k4, a1, a2, u0, h1, s, h2, c2, g, c1, e, tau = p
    y = np.empty(u.size)
    x1, x2, dt = x10, x20, TS / substeps
    lag = int(np.floor(tau / dt))  # the delay in whole Euler steps, and the fraction of one
    frac = tau / dt - lag
    q1 = k1 * max(x1 - c1, 0.0) ** a1
    for i in range(u.size):
        y[i] = x2 + e * q1
        for j in range(substeps):
            m = i * substeps + j - lag  # the step whose input arrives now (before the record: its first sample)
            ud = (1.0 - frac) * u[max(m, 0) // substeps] + frac * u[max(m - 1, 0) // substeps]
            inflow = k4 * max(ud - u0, 0.0)
            q1 = k1 * max(x1 - c1, 0.0) ** a1
            d1 = inflow - q1
            spill = 0.0
            if x1 >= h1 and d1 > 0.0:
                spill, d1 = d1, 0.0
            d2 = g * q1 + s * spill - k3 * max(x2 - c2, 0.0) ** a2
            x1 = min(x1 + dt * d1, h1)
            x2 = min(x2 + dt * d2, h2)
    return y


def _full(theta: np.ndarray, free: tuple[str, ...]) -> np.ndarray:
    vals = dict(FIXED, **dict(zip(free, theta)))
    return np.array([vals[n] for n in NAMES], float)


#: a start's draw of a coefficient (uniform over these), and the fixed start of the others (0 where not listed)
_DRAWN = {
    "k1": (0.02, 0.2),
    "k3": (0.02, 0.2),
    "k4": (0.01, 0.1),
    "h1": (8.0, 12.0),
    "s": (0.0, 1.5),
    "tau": (0.0, 8.0),
}
_START = {"a1": 0.5, "a2": 0.5, "h2": 10.05, "g": 1.0}


def _first_guess(name: str, rng: np.random.Generator) -> float:
    return float(rng.uniform(*_DRAWN[name])) if name in _DRAWN else _START.get(name, 0.0)


def fit(u: np.ndarray, y: np.ndarray, free: tuple[str, ...], starts: int, seed: int, substeps: int) -> Any:
    """The least-squares fit of ``free`` and both start levels to the free-run error on (u, y), best of ``starts``
    starts drawn with ``seed``; ``.x`` holds the parameters then x10, x20, ``.cost`` half the SSE."""
    rng = np.random.default_rng(seed)
    lo = [BOUNDS[n][0] for n in free] + [0.0, 0.0]
    hi = [BOUNDS[n][1] for n in free] + [15.0, 12.0]

    def residual(z: np.ndarray) -> np.ndarray:
        return simulate(u, _full(z[:-2], free), z[-2], z[-1], substeps) - y

    best = None
    for _ in range(starts):
        z0 = [_first_guess(n, rng) for n in free] + [float(rng.uniform(2.0, 10.0)), float(y[0])]
        res = least_squares(residual, z0, bounds=(lo, hi), max_nfev=500, x_scale="jac")
        if best is None or res.cost < best.cost:
            best = res
    return best


def window_start(u: np.ndarray, y: np.ndarray, p: np.ndarray, window: int, substeps: int) -> tuple[float, float]:
    """Start levels (x10, x20) [V] that fit the first ``window`` samples of (u, y), the upper level started from
    1, 2, …, 14 V."""
    fits = [
        least_squares(
            lambda z: simulate(u[:window], p, z[0], z[1], substeps) - y[:window],
            [a, float(y[0])],
            bounds=([0.0, 0.0], [15.0, 12.0]),
        )
        for a in np.linspace(1.0, 14.0, 14)
    ]
    best = min(fits, key=lambda r: r.cost)  # the first of equal costs, as a strict-improvement loop keeps
    return float(best.x[0]), float(best.x[1])


def run(starts: int = 16, seed: int = 0, substeps: int = 8) -> list[dict[str, Any]]:
    """One row per rung of :data:`RUNGS`: RMSE [V] on the estimation record and on the tests (module docstring):
    ``test_estimation_start`` from the estimation fit's levels, ``test`` and ``test-official`` from levels fitted on
    each test's own initialisation window (the dataset's: 4 and 50 samples), scored after it."""
    from benchmarks.datasets import load_dataset
    from sysid.evaluation.metrics import rmse

    data = load_dataset("cascaded-tanks")
    ue, ye = (np.asarray(v, float) for v in (data.est_records[0].u, data.est_records[0].output))
    ut, yt = (np.asarray(v, float) for v in (data.tests["test"].u, data.tests["test"].output))
    rows = []
    for label, free in RUNGS:
        best = fit(ue, ye, free, starts, seed, substeps)
        p = _full(best.x[:-2], free)
        row = {"rung": label, "n_params": len(free) + 2, "estimation": float(np.sqrt(2 * best.cost / ye.size))}
        w = data.init_for("test")
        row["test_estimation_start"] = rmse(yt, simulate(ut, p, best.x[-2], yt[0], substeps), skip=w)
        for test in ("test", "test-official"):  # the same samples; their windows differ
            w = data.init_for(test)
            row[test] = rmse(yt, simulate(ut, p, *window_start(ut, yt, p, w, substeps), substeps), skip=w)
        row["fitted_on_test"] = float(np.sqrt(2 * fit(ut, yt, free, starts, seed, substeps).cost / yt.size))
        row["params"] = dict(zip(free, (float(v) for v in best.x[:-2])))
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.tanks_ladder", description=__doc__.splitlines()[0])
    ap.add_argument("--starts", type=int, default=16)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--substeps", type=int, default=8)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    if args.starts < 1 or args.substeps < 1:
        print("tanks_ladder: --starts and --substeps must be at least 1", file=sys.stderr)
        return 2
    rows = run(args.starts, args.seed, args.substeps)
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print("| rung | parameters | estimation | test, estimation start | test, window 4 | test-official, window 50 "
          "| class fitted on the test |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['rung']} | {r['n_params']} | {r['estimation']:.3f} | {r['test_estimation_start']:.3f} "
            f"| {r['test']:.3f} | {r['test-official']:.3f} | {r['fitted_on_test']:.3f} |"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
