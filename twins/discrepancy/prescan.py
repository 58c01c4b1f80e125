"""Starting values of an added effect's parameters: a scan by estimation SSE before the least-squares fit.

Least squares from the configured values finds the nearest local minimum; the cost of a delay-like parameter
(a time of flight, a path length, an echo delay) oscillates with the carrier period and has many. The scan
therefore tries, in order: the shifts the data show, linearised per parameter; the values the residual
features suggest, jointly; each value of a list-valued parameter; a grid over each parameter's documented
range with two finer zooms (and a continuation in the record length where the grid finds a rough landscape);
and finally each echo-delay-consistent path length refined within ±5 %.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from twins.base import Twin, param_info

from . import features as ft
from .fields import echo_path_guesses, grid, guesses
from .prediction import simulate, sse

__all__ = ["prescan", "continuation_scan"]


class _Search:
    """The best values found so far and their estimation SSE."""

    def __init__(self, tw: Twin, est: Record, skip: int, start: dict[str, Any]):
        self.tw, self.est, self.skip = tw, est, skip
        self.info = param_info(type(tw.params))
        self.best = self.start = start
        #: the whole record simulated at the start (None where it fails): its cost, and the first arrival's search
        self.y_start = self.simulate(start)
        self.best_cost = float("inf") if self.y_start is None else sse(est.output, self.y_start, skip)

    def simulate(self, vals: dict[str, Any]) -> np.ndarray | None:
        try:
            return simulate(self.tw.with_params(**vals), self.est)
        except (ConfigError, DataError, ValueError, FloatingPointError):
            return None

    def cost(self, vals: dict[str, Any]) -> float:
        y = self.simulate(vals)
        return float("inf") if y is None else sse(self.est.output, y, self.skip)

    def offer(self, trial: dict[str, Any], c: float | None = None) -> float:
        """Keep ``trial`` when it is better; returns its cost."""
        c = self.cost(trial) if c is None else c
        if c < self.best_cost:
            self.best_cost, self.best = c, trial
        return c

    def range(self, f: str) -> tuple[float, float]:
        lo, hi = self.info[f].bounds()
        return lo, hi

    def is_int(self, f: str) -> bool:
        return isinstance(getattr(self.tw.params, f), int)


def prescan(
    tw: Twin, est: Record, fields: list[str], a: dict[str, Any], points: int, skip: int, choices: Sequence[str] = ()
) -> dict[str, Any]:
    """Coordinate-wise scan of each effect parameter over its range and the feature guesses (est SSE);
    parameters with a list of values (``choices``) are tried value by value."""
    start: dict[str, Any] = {f: float(getattr(tw.params, f)) for f in fields}
    start.update({f: getattr(tw.params, f) for f in choices})
    s = _Search(tw, est, skip, start)
    lin_guess = _shift_guesses(s, fields, a)
    _joint_guesses(s, fields, a, lin_guess)
    for f in choices:
        for v in s.info[f].choices or ():
            s.offer({**s.best, f: v})
    for _sweep in range(2 if len(fields) > 1 else 1):
        for f in fields:
            _sweep_field(s, f, a, points, lin_guess.get(f, []))
    for f in fields:
        if not s.is_int(f):
            _echo_basins(s, f, a)
    return s.best


def _shift_guesses(s: _Search, fields: list[str], a: dict[str, Any] | None = None) -> dict[str, list[float]]:
    """Delay-like parameters whatever their unit (temperature, distance, …): the shift of the simulated output
    is linearised with respect to each parameter and solved for the shifts the data show. The shifts are
    measured from the first arrival over a sixteenth of the record (before late phase-amplified arrivals), at
    the three best peaks of the cross-correlation (a narrow-band signal leaves the carrier cycle ambiguous), and
    the residual features' shift over the whole record is added (``a["delay"]``). The first arrival is found on
    the whole record's simulation: at 44 MHz the first eighth of 10 420 samples (30 µs) ends before the 67 µs
    time of flight of 100 mm of water, and the shifts measured there were noise (a 7.7 K temperature error's
    trial ended on its range's bound, validation NRMSE 0.28 against 0.027 for the distance trial)."""
    est, best = s.est, s.best
    lin_guess: dict[str, list[float]] = {}
    y_all = s.y_start
    if y_all is None or s.best is not s.start:
        y_all = simulate(s.tw.with_params(**best), est)
    big = np.flatnonzero(np.abs(y_all) > 0.05 * (np.max(np.abs(y_all)) or 1.0))
    i0 = max(int(big[0]) - 16, 0) if big.size else 0
    m = min(len(est), max(len(est) // 8, min(len(est), 256), i0 + max(128, len(est) // 16)))
    part = est[:m]
    y0 = simulate(s.tw.with_params(**best), part)
    win = slice(i0, min(m, i0 + max(128, len(est) // 16)))
    shifts = list(
        ft.delay_candidates(
            part.output[win], y0[win], part.fs, max_shift_s=max(32, (win.stop - win.start) // 8) / part.fs
        )
    )
    whole = float((a or {}).get("delay", {}).get("shift_s", float("nan")))
    if math.isfinite(whole) and whole != 0.0 and all(abs(whole - v) * est.fs > 0.5 for v in shifts):
        shifts.append(whole)
    if not (shifts and max(abs(v) for v in shifts) * est.fs > 0.02):
        return lin_guess
    for f in fields:
        lo, hi = s.range(f)
        dx = 0.002 * (hi - lo)
        x1 = best[f] + dx if best[f] + dx <= hi else best[f] - dx
        try:
            y1 = simulate(s.tw.with_params(**{**best, f: x1}), part)
        except (ConfigError, DataError, ValueError):
            continue
        sh = ft.delay_estimate(y1, y0, part.fs, max_shift_s=8 / part.fs)["shift_s"]
        if abs(sh) * est.fs > 1e-4:
            lin_guess[f] = [best[f] + t * (x1 - best[f]) / sh for t in shifts]
    return lin_guess


def _joint_guesses(s: _Search, fields: list[str], a: dict[str, Any], lin_guess: dict[str, list[float]]) -> None:
    """A joint start from the feature guesses (e.g. echo delay and amplitude together), for the fields that
    have one (at most 8 values each, 96 combinations)."""
    guess = {}
    for f in fields:
        lo, hi = s.range(f)
        g = [v for v in guesses(f, s.info[f].unit, a, s.tw, s.best[f])[::-1] + lin_guess.get(f, []) if lo <= v <= hi]
        if g:
            guess[f] = g
    if not guess:
        return
    keys = list(guess)
    for combo in itertools.islice(itertools.product(*(guess[k][:8] for k in keys)), 96):
        trial = dict(s.best)
        trial.update(
            {k: (int(round(v)) if isinstance(getattr(s.tw.params, k), int) else float(v)) for k, v in zip(keys, combo)}
        )
        s.offer(trial)


def _sweep_field(s: _Search, f: str, a: dict[str, Any], points: int, lin: list[float]) -> None:
    """Grid over the range of ``f`` plus its guesses; a continuation scan where the grid shows several local
    minima; then two zooms around the best value (the cost of a delay-like parameter oscillates)."""
    lo, hi = s.range(f)
    is_int = s.is_int(f)
    g = grid(lo, hi, points, is_int)
    cands = list(g) + [v for v in lin + guesses(f, s.info[f].unit, a, s.tw, s.best[f]) if lo <= v <= hi]
    base_vals = dict(s.best)
    costs = [s.offer({**base_vals, f: int(round(v)) if is_int else float(v)}) for v in cands]
    gc = np.array(costs[: len(g)])
    n_min = int(np.sum((gc[1:-1] < gc[:-2]) & (gc[1:-1] < gc[2:]))) if gc.size > 2 else 0
    if n_min >= 2 and not is_int:
        # a rough landscape (several local minima: phase-sensitive parameters such as a time of flight through a
        # reverberant gap): the cost of a short prefix (fewer late, phase-amplified arrivals) has wide basins
        x = continuation_scan(s.tw, s.est, base_vals, f, lo, hi, points, s.skip, lin)
        s.offer({**base_vals, f: x})
    if is_int:
        return
    geo = lo > 0 and hi / lo > 30
    step = (np.log(hi / lo) if geo else (hi - lo)) / max(points - 1, 1)
    for _z in range(2):
        x = float(s.best[f])
        if geo:
            zg = np.exp(np.linspace(np.log(x) - step, np.log(x) + step, points))
        else:
            zg = np.linspace(x - step, x + step, points)
        for v in zg:
            if lo <= v <= hi:
                s.offer({**s.best, f: float(v)})
        step /= (points - 1) / 2.0


def _echo_basins(s: _Search, f: str, a: dict[str, Any]) -> None:
    """Echo-delay basins: the cost of a path length oscillates with the carrier period, so a guess from the
    measured echo delay (accurate to a fraction of a period, a few % in τ) may sit on a slope or a ridge of its
    basin and lose to a wrong basin's minimum that the grid and zoom happened to refine. Each delay-consistent
    length is therefore refined within ±5 % before the basins are compared (by estimation SSE, at the current
    amplitudes: at a fixed amplitude of the right sign, the ordering of the basins is that of their correlation
    with the residual, the same as with each basin's own optimal amplitude)."""
    lo, hi = s.range(f)
    gs = sorted({round(g, 12) for g in echo_path_guesses(s.info[f].unit, a, s.tw) if lo <= g <= hi})
    for g in gs:
        grid_ = np.clip(g * (1.0 + np.linspace(-0.05, 0.05, 41)), lo, hi)
        costs = [s.cost({**s.best, f: float(v)}) for v in grid_]
        i = int(np.argmin(costs))
        x, cx = float(grid_[i]), float(costs[i])
        h = float(grid_[1] - grid_[0]) if grid_.size > 1 else 0.0
        if h > 0:
            best = s.best
            r = minimize_scalar(
                lambda v: s.cost({**best, f: float(v)}),  # noqa: B023 (used up in this iteration)
                bounds=(max(lo, x - h), min(hi, x + h)),
                method="bounded",
                options={"maxiter": 12, "xatol": h * 1e-3},
            )
            if r.fun < cx:
                x, cx = float(r.x), float(r.fun)
        if cx < s.best_cost:
            s.best_cost, s.best = cx, {**s.best, f: x}


def continuation_scan(
    tw: Twin,
    est: Record,
    vals: dict[str, Any],
    f: str,
    lo: float,
    hi: float,
    points: int,
    skip: int,
    extra: Sequence[float] = (),
) -> float:
    """Scan of ``f`` on the first eighth of the record: a coarse grid over the range, a dense one around the
    configured value (the prior) and the ``extra`` guesses; the four best points are refined by a bounded 1-D
    search; the winner is then re-refined on a quarter, a half and the whole record (continuation in the record
    length: late, phase-amplified arrivals narrow the basins)."""
    n = len(est)

    def cost_on(part: Record, v: float) -> float:
        try:
            return sse(part.output, simulate(tw.with_params(**{**vals, f: float(v)}), part), min(skip, len(part) - 1))
        except (ConfigError, DataError, ValueError, FloatingPointError):
            return float("inf")

    x0 = float(vals[f])
    coarse = np.linspace(lo, hi, 6 * points)
    local = np.linspace(x0 - 0.1 * (hi - lo), x0 + 0.1 * (hi - lo), 6 * points)  # the configured value is the prior
    first = np.concatenate([coarse, local, [v for v in extra if lo <= v <= hi]])
    first = first[(first >= lo) & (first <= hi)]
    part = est[: max(n // 8, min(n, 64))]
    costs = np.array([cost_on(part, v) for v in first])
    step = 0.2 * (hi - lo) / (6 * points - 1)
    cands = []
    for i in np.argsort(costs)[:4]:
        v = float(first[i])
        r = minimize_scalar(
            lambda x: cost_on(part, x),
            bounds=(max(lo, v - step), min(hi, v + step)),
            method="bounded",
            options={"maxiter": 14, "xatol": step * 1e-3},
        )
        cands.append((float(r.fun), float(r.x)) if r.fun < costs[i] else (float(costs[i]), v))
    best_x = min(cands)[1]
    for frac in (4, 2, 1):
        part = est[: max(n // frac, min(n, 64))]
        r = minimize_scalar(
            lambda x: cost_on(part, x),  # noqa: B023 (used up in this iteration)
            bounds=(max(lo, best_x - step / 4), min(hi, best_x + step / 4)),
            method="bounded",
            options={"maxiter": 14, "xatol": step * 1e-4},
        )
        if r.fun <= cost_on(part, best_x):
            best_x = float(r.x)
    return best_x
