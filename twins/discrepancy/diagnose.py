"""The discrepancy loop: calibrate, analyse the residual, name the cause, extend the twin, measure the gain.

``diagnose(twin, data, val)`` (issue 8):

0. **Saturation** (:func:`features.saturation_rails`): where a measured record sits exactly at its extreme value
   on a flat top while the given configuration predicts beyond it, the instrument clipped (e.g. an 8-bit scope at
   ±50 V). Those samples are censored: every prediction of that record is compared *clipped to the rails*, as
   the instrument would have shown it. Without this, a validation record that clips leaves a residual made of
   the clipping (for the acoustic twin's 0.4 V validation chirp 10.9 V RMS against 0.8 V of hidden crosstalk)
   that no candidate can explain and that hides every small effect. The rails are detected once, with the
   configuration as given, and reported under ``saturation``; rounding (quantisation) stays unpredictable.
1. **Calibrate** the twin's current configuration (its ``CALIBRATION_PARAMS``) to the estimation record, with
   the measurement-noise effect switched off so that the simulation is the deterministic prediction.
2. **Analyse** the residual ``e = y − ŷ`` on estimation and validation data
   (:func:`twins.discrepancy.features.analyse`).
3. **Trial every catalog effect** the configuration lacks: add it, pre-scan each of its parameters over its
   documented range (plus the values the residual features suggest, e.g. the echo delay), then fit its
   parameters together with the core calibration parameters by free-run output error
   (:func:`twins.calibration.calibrate`, bounded by the ``pfield`` ranges), re-simulate the validation record.
   The validation gain of the trial is the decisive evidence; the signature score
   (:mod:`twins.discrepancy.evidence`) explains it in numbers and breaks ties.
4. **Significance** of a gain (documented criterion): an F-test on the validation residual variance,
   ``F = (N_eff − p)/p · (s₀² − s₁²)/s₁²`` with ``p`` the number of added parameters and ``N_eff`` the effective
   number of independent residual samples (:func:`features.effective_samples`), Bonferroni-corrected over the
   candidates tried (``p_value < alpha / n_candidates``), *and* a relative validation NRMSE reduction of at
   least ``min_rel_gain`` (a floor against gains of no practical size on very long records). The floor was
   kept: the acoustic crosstalk and even-order cases that stayed under it (0.1–0.7 %) did so because the
   uncensored clipping of the validation record dominated the residual; with step 0 they gain 27–86 %.
5. **Group** what the data cannot tell apart: candidates of the leading cause's ``EffectSpec.group`` whose gain
   reaches half of it, and any candidate whose validation residual variance is within the sampling error
   ``2·√(2/N_eff)`` of the leader's while its prediction differs from the leader's by less than half the
   residual RMS. The group is reported with the experiment that would separate it.
6. **Extend**: keep the leading cause if significant, repeat (at most ``max_rounds``) until nothing significant
   remains. Then test what is left for structure no catalog entry explains: a generic linear-in-parameters
   residual model (FIR of u, (u²)′, (u³)′ and a trend), fitted on the estimation residual, scored on the
   validation residual with the same F-test; if significant it is described in generic terms.

Issue 20 around this loop: the split must leave excitation in the validation record and the twin's ranges
follow the records (:mod:`.realdata`); effects that are on are re-tested after the baseline (:mod:`.defaults`);
the verdict is ``unexplained`` when the final residual stays far above the noise measured from the data.

Confidence of a cause (in [0, 1]): ``(1 − p_value) · (0.5 + 0.5·√(1 − g₂/g₁)) · (0.8 + 0.2·s)`` with ``g₁`` its
relative validation gain, ``g₂`` the best gain of a candidate outside its group and ``s`` its signature score
(the clearer of the estimation and validation records): 1 when only this effect explains the data and its
signature is clear, ½ when another effect explains it about as well.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, Iterable, Sequence

import numpy as np
from scipy import stats

from sysid.errors import ConfigError, DataError
from sysid.metrics import nrmse, r2
from sysid.progress import progress as progress_bar
from sysid.record import Record
from twins.base import Twin, param_info
from twins.calibration import calibrate as ls_calibrate

from . import defaults as dflt
from . import evidence as ev
from . import features as ft
from . import realdata

__all__ = ["diagnose", "NOISE_EFFECTS", "significance"]

#: effects that model unpredictable noise: never a candidate cause, always off in the fitted prediction
NOISE_EFFECTS: tuple[str, ...] = ("measurement_noise",)


# ---------------------------------------------------------------------------------------------- helpers
def _unpredictable(twin: Twin) -> set[str]:
    """Effects that add error no prediction can follow: noise, and quantisation (its error depends on the
    noise); they are left out of the fitted prediction and are judged by their data signature only."""
    return {e for e, s in twin.EFFECTS.items() if e in NOISE_EFFECTS or ev.family_of(s) in ("noise", "quantization")}


def _deterministic(twin: Twin) -> Twin:
    """The same twin without its noise and quantisation effects (the prediction to compare with data)."""
    eff = set(twin.effects) - _unpredictable(twin)
    return twin if eff == set(twin.effects) else twin.with_effects(eff)


#: meta key under which diagnose() attaches the saturation rails to its working copies of the records
_RAILS = "diagnose_saturation_rails"


def _simulate(twin: Twin, rec: Record) -> np.ndarray:
    """The twin's output for ``rec.u``, clipped to the record's saturation rails when it has any."""
    return ft.clip_to_rails(np.asarray(twin.simulate(rec.u, rec.fs), dtype=float), rec.meta.get(_RAILS))


def _with_rails(rec: Record, rails: dict[str, Any]) -> Record:
    if rails.get("lo") is None and rails.get("hi") is None:
        return rec
    return rec.replace(meta={**rec.meta, _RAILS: {"lo": rails["lo"], "hi": rails["hi"]}})


def _continues(est: Record, val: Record) -> bool:
    """True when ``val`` directly continues ``est`` (same source and fs, ``t0`` at the end of ``est``, as
    ``Record.split`` makes them): the validation is then simulated as the continuation of the estimation input
    (still free run, no measured output used), so a system with memory (hysteresis, creep) is not restarted."""
    if val.fs != est.fs or "t0" not in val.meta or est.source != val.source:
        return False
    t_end = float(est.meta.get("t0", 0.0)) + len(est) / est.fs
    return abs(float(val.meta["t0"]) - t_end) < 0.5 / est.fs


def _simulate_val(twin: Twin, est: Record, val: Record) -> np.ndarray:
    if _continues(est, val):
        y = _simulate(twin, Record(u=np.concatenate([est.u, val.u]), y=None, fs=est.fs))[len(est):]
        return ft.clip_to_rails(y, val.meta.get(_RAILS))
    return _simulate(twin, val)


def significance(sse0: float, sse1: float, n_eff: float, p_extra: int) -> float:
    """p-value of the F-test that the residual variance fell from sse0 to sse1 by adding ``p_extra`` parameters,
    with ``n_eff`` effective independent samples (see the module docstring)."""
    p = max(int(p_extra), 1)
    if not (math.isfinite(sse0) and math.isfinite(sse1)) or sse1 >= sse0 or sse1 <= 0:
        return 1.0 if sse1 > 0 or sse1 >= sse0 else 0.0
    d2 = max(n_eff - p, 1.0)
    F = d2 / p * (sse0 - sse1) / sse1
    return float(stats.f.sf(F, p, d2))


def _numeric_fields(twin: Twin, fields: Iterable[str]) -> list[str]:
    info = param_info(type(twin.params))
    out = []
    for f in fields:
        if f not in info or f in out:
            continue
        v = getattr(twin.params, f)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        lo, hi = info[f].range
        if lo is None or hi is None or not (float(hi) > float(lo)):
            continue
        out.append(f)
    return out


def _choice_fields(twin: Twin, fields: Iterable[str]) -> list[str]:
    """Effect parameters that take one of a list of values (e.g. a fluid name): scanned, never least-squares fitted."""
    info = param_info(type(twin.params))
    return [f for f in fields if f in info and info[f].choices]


def _int_fields(twin: Twin, fields: Iterable[str]) -> list[str]:
    return [f for f in fields if isinstance(getattr(twin.params, f, None), int)
            and not isinstance(getattr(twin.params, f, None), bool)]


def _grid(lo: float, hi: float, n: int, is_int: bool) -> np.ndarray:
    if lo > 0 and hi / lo > 30:
        g = np.geomspace(lo, hi, n)
    else:
        g = np.linspace(lo, hi, n)
    if is_int:
        g = np.unique(np.round(g))
    return g


def _guesses(field: str, unit: str, a: dict[str, Any], twin: Twin, current: float) -> list[float]:
    """Values of an effect parameter that the residual features suggest (delays, path lengths, amplitudes)."""
    u = (unit or "").strip().lower()
    name = field.lower()
    sh = a["delay"]["shift_s"]
    tau = a["echo"].get("lag_s", float("nan"))
    coef = a["echo"].get("coef", 0.0)
    # echo delays: the main peak, then the strongest peaks at shorter lags (below the signal's correlation length,
    # where the main search does not look: an echo that close is confounded with shape errors but still a guess)
    taus = [tau] + [t for t in a["echo"].get("short_lags_s", []) if math.isfinite(t)]
    out: list[float] = []
    if u in ("s", "sec", "seconds"):
        out += [sh, abs(sh), current + sh]
        if math.isfinite(tau):
            out += [tau]
    elif u in ("us", "µs"):
        out += [sh * 1e6, current + sh * 1e6] + ([tau * 1e6] if math.isfinite(tau) else [])
    elif u in ("ms",):
        out += [sh * 1e3, current + sh * 1e3] + ([tau * 1e3] if math.isfinite(tau) else [])
    elif u in ("samples", "sample"):
        out += [a["delay"]["shift_samples"], current + a["delay"]["shift_samples"]]
        if math.isfinite(tau):
            out += [tau * a["fs"]]
    elif u == "m" or u == "mm":
        c = ev.sound_speed(twin)
        k = 1e3 if u == "mm" else 1.0
        if c:
            out += [k * c * sh, current + k * c * sh]
            out += _echo_path_guesses(unit, a, twin)
    if any(w in name for w in ("amp", "gain", "coef", "reflect", "level", "scale")) and u in ("", "1", "-", "ratio"):
        out += [coef, abs(coef)]
    return [float(v) for v in out if math.isfinite(v)]


def _echo_path_guesses(unit: str, a: dict[str, Any], twin: Twin) -> list[float]:
    """Lengths [m or mm] that the measured echo delays τ (main peak of the residual–output lag regression, then
    the strongest shorter-lag peaks) imply for a path-length parameter: an extra path c·τ, a round trip c·τ/2,
    and a lateral image source (a wall at distance w beside a path of length L: √(L² + 4w²) − L = c·τ)."""
    u = (unit or "").strip().lower()
    c = ev.sound_speed(twin)
    if u not in ("m", "mm") or not c:
        return []
    k = 1e3 if u == "mm" else 1.0
    taus = [a["echo"].get("lag_s", float("nan"))] + [t for t in a["echo"].get("short_lags_s", []) if math.isfinite(t)]
    L = getattr(twin.params, "distance_m", None)
    out: list[float] = []
    for j, t in enumerate(taus):
        if not math.isfinite(t) or t <= 0:
            continue
        if j == 0:
            out += [k * c * t, k * c * t / 2]
        if isinstance(L, (int, float)) and L > 0:
            out += [k * math.sqrt(max((L + c * t) ** 2 - L * L, 0.0)) / 2]
    return [float(v) for v in out if math.isfinite(v) and v > 0]


def _core_for(twin: Twin, core: Sequence[str]) -> list[str]:
    """Core calibration parameters that act in this configuration: a parameter that belongs only to effects
    that are switched off has no effect on the output and is not fitted."""
    owned_off = set()
    owned_on = set()
    for e, spec in twin.EFFECTS.items():
        (owned_on if e in twin.effects else owned_off).update(spec.params.values())
    return [c for c in core if c not in owned_off or c in owned_on]


# ---------------------------------------------------------------------------------------------- trials
@dataclasses.dataclass
class Trial:
    effect: str
    twin: Twin
    fitted: dict[str, float]
    effect_params: dict[str, float]
    stderr: dict[str, float]
    sse_est: float
    sse_val: float
    yhat_val: np.ndarray
    nrmse_val: float
    r2_val: float
    p_value: float = 1.0
    gain: float = 0.0
    significant: bool = False
    seconds: float = 0.0
    n_added: int = 0
    base: Any = None


def _sse(y: np.ndarray, yh: np.ndarray, skip: int) -> float:
    r = np.asarray(y, float)[skip:] - np.asarray(yh, float)[skip:]
    v = float(np.sum(r * r))
    return v if math.isfinite(v) else float("inf")


def _continuation_scan(tw: Twin, est: Record, vals: dict[str, Any], f: str, lo: float, hi: float, points: int,
                       skip: int, extra: Sequence[float] = ()) -> float:
    """Scan of ``f`` on the first eighth of the record: a coarse grid over the range, a dense one around the
    configured value (the prior) and the ``extra`` guesses; the six best points are refined by a bounded 1-D
    search; the winner is then re-refined on a quarter, a half and the whole record (continuation in the record
    length: late, phase-amplified arrivals narrow the basins)."""
    from scipy.optimize import minimize_scalar

    n = len(est)

    def cost_on(part: Record, v: float) -> float:
        try:
            return _sse(part.y, _simulate(tw.with_params(**{**vals, f: float(v)}), part), min(skip, len(part) - 1))
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
        r = minimize_scalar(lambda x: cost_on(part, x), bounds=(max(lo, v - step), min(hi, v + step)),
                            method="bounded", options={"maxiter": 14, "xatol": step * 1e-3})
        cands.append((float(r.fun), float(r.x)) if r.fun < costs[i] else (float(costs[i]), v))
    best_x = min(cands)[1]
    for frac in (4, 2, 1):
        part = est[: max(n // frac, min(n, 64))]
        r = minimize_scalar(lambda x: cost_on(part, x), bounds=(max(lo, best_x - step / 4), min(hi, best_x + step / 4)),
                            method="bounded", options={"maxiter": 14, "xatol": step * 1e-4})
        if r.fun <= cost_on(part, best_x):
            best_x = float(r.x)
    return best_x


def _prescan(tw: Twin, est: Record, fields: list[str], a: dict[str, Any], points: int, skip: int,
             choices: Sequence[str] = ()) -> dict[str, Any]:
    """Coordinate-wise scan of each effect parameter over its range and the feature guesses (est SSE);
    parameters with a list of values (``choices``) are tried value by value."""
    info = param_info(type(tw.params))
    best: dict[str, Any] = {f: float(getattr(tw.params, f)) for f in fields}
    best.update({f: getattr(tw.params, f) for f in choices})
    y = est.y

    def cost(vals: dict[str, float]) -> float:
        try:
            return _sse(y, _simulate(tw.with_params(**vals), est), skip)
        except (ConfigError, DataError, ValueError, FloatingPointError):
            return float("inf")

    best_cost = cost(best)
    # delay-like parameters whatever their unit (temperature, distance, …): linearise the shift of the simulated
    # output with respect to each parameter and solve for the shifts the data show. The shifts are measured on
    # the first eighth of the record (the first arrivals, before late phase-amplified ones), at the three best
    # peaks of the cross-correlation (a narrow-band signal leaves the carrier cycle ambiguous).
    lin_guess: dict[str, list[float]] = {}
    m = max(len(est) // 8, min(len(est), 256))
    part = est[:m]
    y0 = _simulate(tw.with_params(**best), part)
    # window: from the first arrival of the simulated output over a sixteenth of the record
    big = np.flatnonzero(np.abs(y0) > 0.05 * (np.max(np.abs(y0)) or 1.0))
    i0 = max(int(big[0]) - 16, 0) if big.size else 0
    win = slice(i0, min(m, i0 + max(128, len(est) // 16)))
    shifts = ft.delay_candidates(part.y[win], y0[win], part.fs, max_shift_s=max(32, (win.stop - win.start) // 8) / part.fs)
    if shifts and max(abs(v) for v in shifts) * est.fs > 0.02:
        for f in fields:
            lo, hi = (float(v) for v in info[f].range)
            dx = 0.002 * (hi - lo)
            x1 = best[f] + dx if best[f] + dx <= hi else best[f] - dx
            try:
                y1 = _simulate(tw.with_params(**{**best, f: x1}), part)
            except (ConfigError, DataError, ValueError):
                continue
            sh = ft.delay_estimate(y1, y0, part.fs, max_shift_s=8 / part.fs)["shift_s"]
            if abs(sh) * est.fs > 1e-4:
                lin_guess[f] = [best[f] + t * (x1 - best[f]) / sh for t in shifts]
    # joint start from the feature guesses (e.g. echo delay and amplitude together), when every field has one
    guess = {}
    for f in fields:
        lo, hi = (float(v) for v in info[f].range)
        g = [v for v in _guesses(f, info[f].unit, a, tw, best[f])[::-1] + lin_guess.get(f, []) if lo <= v <= hi]
        if g:
            guess[f] = g
    if guess:
        import itertools

        keys = list(guess)
        for combo in itertools.islice(itertools.product(*(guess[k][:8] for k in keys)), 96):
            trial = dict(best)
            trial.update({k: (int(round(v)) if isinstance(getattr(tw.params, k), int) else float(v))
                          for k, v in zip(keys, combo)})
            c = cost(trial)
            if c < best_cost:
                best_cost, best = c, trial
    for f in choices:
        for v in info[f].choices or ():
            trial = dict(best)
            trial[f] = v
            c = cost(trial)
            if c < best_cost:
                best_cost, best = c, trial
    for _sweep in range(2 if len(fields) > 1 else 1):
        for f in fields:
            lo, hi = (float(v) for v in info[f].range)
            is_int = isinstance(getattr(tw.params, f), int)
            grid = _grid(lo, hi, points, is_int)
            cands = list(grid) + [g for g in lin_guess.get(f, []) + _guesses(f, info[f].unit, a, tw, best[f])
                                  if lo <= g <= hi]
            base_vals = dict(best)
            costs = []
            for v in cands:
                trial = dict(base_vals)
                trial[f] = int(round(v)) if is_int else float(v)
                c = cost(trial)
                costs.append(c)
                if c < best_cost:
                    best_cost, best = c, trial
            gc = np.array(costs[: len(grid)])
            n_min = int(np.sum((gc[1:-1] < gc[:-2]) & (gc[1:-1] < gc[2:]))) if gc.size > 2 else 0
            if n_min >= 2 and not is_int:
                # a rough landscape (several local minima: phase-sensitive parameters such as a time of flight
                # through a reverberant gap). Continuation in the record length: the cost of a short prefix
                # (fewer late, phase-amplified arrivals) has wide basins; scan it densely, then zoom while the
                # prefix grows to the whole record.
                x = _continuation_scan(tw, est, base_vals, f, lo, hi, points, skip, lin_guess.get(f, []))
                trial = dict(base_vals)
                trial[f] = x
                c = cost(trial)
                if c < best_cost:
                    best_cost, best = c, trial
            if is_int:
                continue
            # zoom: rescan finer around the best value (the cost of a delay-like parameter oscillates)
            geo = lo > 0 and hi / lo > 30
            step = (np.log(hi / lo) if geo else (hi - lo)) / max(points - 1, 1)
            for _z in range(2):
                x = float(best[f])
                if geo:
                    zg = np.exp(np.linspace(np.log(x) - step, np.log(x) + step, points))
                else:
                    zg = np.linspace(x - step, x + step, points)
                for v in zg:
                    if not lo <= v <= hi:
                        continue
                    trial = dict(best)
                    trial[f] = float(v)
                    c = cost(trial)
                    if c < best_cost:
                        best_cost, best = c, trial
                step /= (points - 1) / 2.0
    # echo-delay basins: the cost of a path length oscillates with the carrier period, so a guess from the measured
    # echo delay (accurate to a fraction of a period, a few % in τ) may sit on a slope or a ridge of its basin and
    # lose to a wrong basin's minimum that the grid/zoom above happened to refine. Each delay-consistent length is
    # therefore refined within ±5 % before the basins are compared (by estimation SSE, at the current amplitudes:
    # at a fixed amplitude of the right sign, the ordering of the basins is that of their correlation with the
    # residual, the same as with each basin's own optimal amplitude).
    for f in fields:
        lo, hi = (float(v) for v in info[f].range)
        if isinstance(getattr(tw.params, f), int):
            continue
        gs = sorted({round(g, 12) for g in _echo_path_guesses(info[f].unit, a, tw) if lo <= g <= hi})
        for g in gs:
            grid = np.clip(g * (1.0 + np.linspace(-0.05, 0.05, 41)), lo, hi)
            costs = []
            for v in grid:
                trial = dict(best)
                trial[f] = float(v)
                costs.append(cost(trial))
            i = int(np.argmin(costs))
            x, cx = float(grid[i]), float(costs[i])
            h = float(grid[1] - grid[0]) if grid.size > 1 else 0.0
            if h > 0:
                from scipy.optimize import minimize_scalar

                r = minimize_scalar(lambda v: cost({**best, f: float(v)}), bounds=(max(lo, x - h), min(hi, x + h)),
                                    method="bounded", options={"maxiter": 12, "xatol": h * 1e-3})
                if r.fun < cx:
                    x, cx = float(r.x), float(r.fun)
            if cx < best_cost:
                best_cost, best = cx, {**best, f: x}
    return best


def _run_trial(base: Twin, effect: str, est: Record, val: Record, core: list[str], a_val: dict[str, Any],
               opts: dict[str, Any], refit_core: bool, start: dict[str, float] | None = None,
               choice: dict[str, Any] | None = None) -> Trial:
    """Add ``effect`` to ``base`` and fit it to ``est``: stage A (``refit_core=False``) fits the effect's own
    parameters after a pre-scan with the core held at its calibration; stage B also refits the core.

    An effect with both a list-valued parameter (a model variant, e.g. Rapp or cubic compression) and numeric
    ones is fitted once per variant (at most 8 combinations) and the variant with the smallest estimation SSE
    is kept: the variants are different structures, each with its own optimum of the numeric parameters
    (choosing the variant at the configured numeric values picks the wrong one when they are far off)."""
    t0 = time.perf_counter()
    spec = base.EFFECTS[effect]
    tw = base.with_effects(set(base.effects) | {effect})
    # integer parameters (element counts, bit depths) are structural choices of the configuration: kept as given
    eff_fields = [f for f in _numeric_fields(tw, spec.params.values()) if f not in _int_fields(tw, spec.params.values())]
    cat_fields = _choice_fields(tw, spec.params.values())
    if start is None and choice is None and cat_fields and eff_fields:
        import itertools

        info = param_info(type(tw.params))
        best: Trial | None = None
        for combo in itertools.islice(itertools.product(*(info[c].choices for c in cat_fields)), 8):
            tr = _run_trial(base, effect, est, val, core, a_val, opts, refit_core, choice=dict(zip(cat_fields, combo)))
            if best is None or tr.sse_est < best.sse_est:
                best = tr
        assert best is not None
        best.seconds = time.perf_counter() - t0
        return best
    if choice is not None:
        tw = tw.with_params(**choice)
        x0 = {**(_prescan(tw, est, eff_fields, a_val, opts["scan_points"], opts["skip"], ()) if eff_fields else {}),
              **choice}
    elif start is None:
        x0 = (_prescan(tw, est, eff_fields, a_val, opts["scan_points"], opts["skip"], cat_fields)
              if (eff_fields or cat_fields) else {})
    else:
        x0 = dict(start)
    fixed = {k: v for k, v in x0.items() if k in cat_fields or k in _int_fields(tw, eff_fields)}
    if fixed:  # categorical and integer parameters stay at their scanned values
        tw = tw.with_params(**{k: (int(round(v)) if k not in cat_fields else v) for k, v in fixed.items()})
    x0 = {k: v for k, v in x0.items() if k not in fixed}
    names = [f for f in eff_fields if f not in fixed]
    if refit_core:
        names += [c for c in _core_for(tw, core) if c not in eff_fields]
    if names:
        res = ls_calibrate(tw, est, names, x0={**{c: float(getattr(base.params, c)) for c in core}, **x0},
                           simulate=_simulate, max_nfev=opts["trial_nfev"] if refit_core else opts["scan_nfev"],
                           skip=opts["skip"])
        fit_tw, fitted, stderr = res.twin, res.fitted, res.stderr
    else:
        fit_tw, fitted, stderr = tw, {}, {}
    yv = _simulate_val(fit_tw, est, val)
    ye = _simulate(fit_tw, est)
    ok = bool(np.all(np.isfinite(yv)))
    eff_all = eff_fields + [c for c in cat_fields if c not in eff_fields]
    tr = Trial(effect=effect, twin=fit_tw, fitted=fitted,
                 effect_params={f: fitted.get(f, getattr(fit_tw.params, f)) for f in eff_all},
                 stderr={f: stderr.get(f, float("nan")) for f in eff_fields},
                 sse_est=_sse(est.y, ye, opts["skip"]), sse_val=_sse(val.y, yv, opts["skip"]), yhat_val=yv,
                 nrmse_val=nrmse(val.y, yv, opts["skip"]) if ok else float("inf"),
                 r2_val=r2(val.y, yv, opts["skip"]) if ok else float("-inf"),
                 seconds=time.perf_counter() - t0, n_added=max(len(eff_fields), 1))
    tr.base = base
    return tr


# ---------------------------------------------------------------------------------------------- stages
@dataclasses.dataclass
class Stage:
    """A configuration with its validation prediction and residual analysis."""

    twin: Twin
    yhat_est: np.ndarray
    yhat_val: np.ndarray
    analysis_est: dict[str, Any]
    analysis_val: dict[str, Any]
    nrmse_val: float
    r2_val: float
    sse_val: float

    def summary(self, also: Iterable[str] = ()) -> dict[str, Any]:
        return {"effects": sorted(set(self.twin.effects) | set(also)), "r2_val": self.r2_val, "nrmse_val": self.nrmse_val,
                "tests": ft.tests_summary(self.analysis_val["_tests_full"])}


def _stage(twin: Twin, est: Record, val: Record, opts: dict[str, Any]) -> Stage:
    ye = _simulate(twin, est)
    yv = _simulate_val(twin, est, val)
    ae = ft.analyse(est.u, est.y, ye, est.fs, est.meta, max_lag=opts["max_lag"], max_echo_s=opts["max_echo_s"])
    av = ft.analyse(val.u, val.y, yv, val.fs, val.meta, max_lag=opts["max_lag"], max_echo_s=opts["max_echo_s"])
    return Stage(twin, ye, yv, ae, av, nrmse(val.y, yv, opts["skip"]), r2(val.y, yv, opts["skip"]),
                 _sse(val.y, yv, opts["skip"]))


def _generic_residual_model(est: Record, val: Record, e_est: np.ndarray, e_val: np.ndarray, lags: int,
                            skip: int) -> dict[str, Any]:
    """Structure no catalog entry explains: a FIR model of the residual on u, (u²)′, (u³)′ (lags 0…L) and a
    trend, fitted on the estimation residual and scored on the validation residual (relative SSE, F-test)."""
    def design(rec: Record) -> np.ndarray:
        u = np.asarray(rec.u, float)
        sc = float(np.std(est.u)) or 1.0
        mu = float(np.mean(est.u))
        z = (u - mu) / sc
        cols = [np.ones_like(z), np.linspace(-1, 1, z.size)]
        for x in (z, z ** 2 - 1.0, z ** 3 - 3 * z):
            for k in range(lags + 1):
                cols.append(np.r_[np.zeros(k), x[: x.size - k]])
        return np.column_stack(cols)
    A = design(est)[skip:]
    # ridge-regularised least squares: lagged copies of a slow input are nearly collinear, and an unregularised
    # fit would extrapolate wildly to the validation record
    G = A.T @ A
    lam = 1e-4 * float(np.mean(np.diag(G))) or 1e-12
    c = np.linalg.solve(G + lam * np.eye(G.shape[0]), A.T @ e_est[skip:])
    pv = design(val)[skip:] @ c
    ev_ = e_val[skip:]
    sse0 = float(ev_ @ ev_)
    sse1 = float((ev_ - pv) @ (ev_ - pv))
    n_eff = ft.effective_samples(ev_ - pv)
    p = significance(sse0, sse1, n_eff, A.shape[1])
    return {"nrmse_ratio": math.sqrt(sse1 / sse0) if sse0 > 0 else 1.0, "p_value": p, "n_terms": int(A.shape[1])}


# ---------------------------------------------------------------------------------------------- main entry
def diagnose(twin: Twin, data: Record, val: Record | None = None, max_rounds: int = 3, *,
             threads: int | None = None, **options: Any) -> dict[str, Any]:
    """Diagnose what ``twin`` gets wrong about ``data`` (issue 8); return the JSON-able result.

    Parameters
    ----------
    twin : Twin
        Starting configuration (parameters and effects); its noise effects are ignored for prediction.
    data, val : Record
        Estimation and validation records. Without ``val`` the data is split at ``split`` of its length.
    max_rounds : int
        At most this many effects are added.
    candidates : list of effect ids
        Catalog effects to try (default: every effect not in the configuration, except noise).
    calibration_params : list of parameter names
        Core parameters refitted with every trial (default ``twin.CALIBRATION_PARAMS``).
    alpha, min_rel_gain : float
        Significance level (Bonferroni over the candidates) and minimum relative validation NRMSE reduction.
    trial_nfev, scan_nfev, scan_points, refine : int
        Budgets: least-squares evaluations of a full trial (effect + core parameters) and of the first-stage
        fit (effect parameters only, core held), points of each parameter pre-scan, and how many of the
        best first-stage candidates get the full refit.

    threads : int or None
        Threads of the twin's compiled (numba) kernels during the diagnosis. Default: 1 for records under
        2²⁰ samples in all — the diagnosis simulates short records thousands of times, and a parallel kernel's
        fork-join costs more than its work there (acoustic twin, 10⁴ samples on a shared 2-core machine:
        17 ms instead of 31 ms CPU per simulation; a whole acoustic diagnosis 48 → 34 s CPU, though 25 → 33 s
        wall time when the second core is idle); None keeps numba's setting for longer records.

    Returns a dict with ``verdict``, ``causes``, ``baseline``, ``extended``, ``gain`` (issue 8) and the details
    ``rounds`` (every trial with its numbers), ``unexplained`` and ``analysis`` (baseline and final residual
    numbers on the validation data).
    """
    try:
        n_total = len(data) + (len(val) if val is not None else 0)
    except TypeError:  # not records: _diagnose names the problem
        n_total = 0
    nt = threads if threads is not None else (1 if n_total < _PARALLEL_FROM else None)
    with _numba_threads(nt):
        return _diagnose(twin, data, val, max_rounds, **options)


_PARALLEL_FROM = 1 << 20  # samples (estimation + validation) from which numba's own thread count is kept


class _numba_threads:
    """Context manager: numba's thread count for the current thread (thread-local in numba), restored after."""

    def __init__(self, n: int | None):
        self.n, self.prev = n, None

    def __enter__(self):
        if self.n is not None:
            try:
                import numba

                self.prev = numba.get_num_threads()
                numba.set_num_threads(max(1, min(int(self.n), numba.config.NUMBA_NUM_THREADS)))
            except ImportError:  # pragma: no cover - numba is a dependency; without it nothing to set
                self.prev = None
        return self

    def __exit__(self, *exc):
        if self.prev is not None:
            import numba

            numba.set_num_threads(self.prev)
        return False


def _diagnose(twin: Twin, data: Record, val: Record | None = None, max_rounds: int = 3, *,
             candidates: Sequence[str] | None = None, calibrate_baseline: bool = True,
             calibration_params: Sequence[str] | None = None, alpha: float = 0.01, min_rel_gain: float = 0.005,
             trial_nfev: int = 25, scan_nfev: int = 15, scan_points: int = 13, refine: int = 3, max_lag: int = 20, max_echo_s: float | None = None,
             skip: int = 0, split: float = 0.6, generic_lags: int = 10, keep_stages: bool = False,
             retest_defaults: bool = True, follow_ranges: bool = True, progress: Any = None) -> dict[str, Any]:
    """The body of :func:`diagnose` (same arguments)."""
    if not isinstance(twin, Twin):
        raise ConfigError("diagnose: twin must be a Twin instance")
    say = progress if callable(progress) else (lambda msg: None)
    # issue 20: a validation that carries excitation, the twin's ranges from the records (realdata.py)
    twin, data, val, split_info, range_notes = realdata.prepare(twin, data, val, split, follow_ranges)
    if data.n_inputs != 1 or data.n_outputs != 1:
        raise DataError(f"{data.source}: diagnose handles single-input single-output records")
    if abs(data.fs - val.fs) > 1e-9 * data.fs:
        raise DataError(f"estimation and validation records have different fs ({data.fs} and {val.fs} Hz)")
    opts = {"trial_nfev": int(trial_nfev), "scan_nfev": int(scan_nfev), "scan_points": int(scan_points), "skip": int(skip), "max_lag": int(max_lag),
            "max_echo_s": max_echo_s}
    unknown = [e for e in (candidates or []) if e not in twin.EFFECTS]
    if unknown:
        raise ConfigError(f"unknown effect {unknown[0]!r} for twin {twin.name}; valid: {', '.join(twin.EFFECTS)}")
    t_start = time.perf_counter()
    core = list(calibration_params if calibration_params is not None else twin.CALIBRATION_PARAMS)
    core = _numeric_fields(twin, core)
    say(f"diagnose {twin.name}: {len(data)} + {len(val)} samples" + "".join(f"; {n}" for n in range_notes))

    # 0. saturation rails of the measured records (censored samples), judged with the configuration as given
    current = _deterministic(twin)
    saturation = {"estimation": ft.saturation_rails(data.y, _simulate(current, data)),
                  "validation": ft.saturation_rails(val.y, _simulate_val(current, data, val))}
    data, val = _with_rails(data, saturation["estimation"]), _with_rails(val, saturation["validation"])
    # the calibration is fitted to the estimation record: only rails there need the rail-aware output error
    railed = saturation["estimation"]["lo"] is not None or saturation["estimation"]["hi"] is not None
    # 1. calibrate the current configuration (deterministic prediction)
    prior = current
    calib_info: dict[str, Any] = {}
    # effects that are on are re-tested after the baseline (defaults.py): their own parameters stay at the
    # configured values in the baseline fit, so that a mis-sized default shows as the re-test's gain
    retest = dflt.retestable(current, _unpredictable(twin), NOISE_EFFECTS) if retest_defaults else []
    held = dflt.owned_fields(current, retest)
    core0 = [c for c in _core_for(current, core) if c not in held]
    if calibrate_baseline and core0:
        say("calibrating the configuration as given")
        try:
            if railed:  # the twin's own calibration does not know the rails: output error on the clipped prediction
                raise TypeError
            res = current.calibrate(data, val=val, names=core0)
        except TypeError:
            res = ls_calibrate(current, data, core0, val=val, simulate=_simulate)
        fitted = _deterministic(res.twin)
        calib_info = {"fitted": res.fitted, "stderr": res.stderr}
        # parameters that end at a bound: the bound widened once and the fit retried (realdata.py)
        fitted, wide_info = realdata.refit_at_bounds(fitted, core0, data, lambda tw: _sse(data.y, _simulate(tw, data), skip),
                                                     _simulate, say)
        calib_info = wide_info or calib_info
        # keep the calibration only if it improves on the configuration as given (an unconverged fit would
        # otherwise hand every trial that restarts from the prior a spurious gain)
        if _sse(data.y, _simulate(fitted, data), skip) <= _sse(data.y, _simulate(current, data), skip):
            current = fitted
        else:
            calib_info["kept"] = False
            calib_info["note"] = "calibration did not improve on the given configuration; the given one is used"
    base = _stage(current, data, val, opts)
    stage = base
    retest_left = list(retest)  # effects that are on, re-tested in every round beside the ones to add
    # trials refit the core without the parameters of the effects that are on: a trial that refitted the creep
    # rate would credit any added effect with the re-test's gain (the re-tests fit those parameters themselves)
    core_r = [c for c in core if c not in held]

    pool = [e for e in (candidates if candidates is not None else twin.EFFECTS)
            if e in twin.EFFECTS and e not in twin.effects and e not in NOISE_EFFECTS
            and e not in _unpredictable(twin)]

    causes: list[dict[str, Any]] = []
    rounds: list[dict[str, Any]] = []
    for rnd in range(max(int(max_rounds), 0)):
        remaining = [e for e in pool if e not in stage.twin.effects]
        if not remaining and not retest_left:
            break
        a_val = stage.analysis_val
        a_fit = dict(a_val)
        a_fit["fs"] = data.fs
        # features that guide the pre-scan come from the estimation residual (the data the trial is fitted to)
        a_fit_est = dict(stage.analysis_est)
        a_fit_est["fs"] = data.fs
        n_eff0 = ft.effective_samples(val.y[skip:] - stage.yhat_val[skip:])
        trials: list[Trial] = []
        # two starting points for the core: the calibrated configuration (which may have bent its core parameters
        # to mimic the missing effect) and the configuration as given (the prior)
        cur_core = _core_for(stage.twin, core)
        prior_base = stage.twin.with_params(**{c: getattr(prior.params, c) for c in cur_core})
        # the prior is tried only where the calibration moved a core parameter by more than 2 % of its value
        moved = any(abs(float(getattr(prior.params, c)) - float(getattr(stage.twin.params, c)))
                    > 0.02 * max(abs(float(getattr(prior.params, c))), 1e-300) for c in cur_core)
        bases = [stage.twin] + ([prior_base] if moved else [])
        for i_e, e in enumerate(progress_bar(remaining, desc=f"diagnose round {rnd + 1}", unit="effect")):
            say(f"round {rnd + 1}: trying {e} ({i_e + 1}/{len(remaining)})")
            best_tr = None
            for b in bases:
                try:
                    tr = _run_trial(b, e, data, val, core_r, a_fit_est, opts, refit_core=False)
                except (ConfigError, DataError, ValueError, np.linalg.LinAlgError) as exc:  # cannot run here
                    rounds.append({"round": rnd + 1, "effect": e, "error": str(exc)})
                    continue
                if best_tr is None or tr.sse_est < best_tr.sse_est:
                    if best_tr is not None:
                        tr.seconds += best_tr.seconds
                    best_tr = tr
            if best_tr is not None:
                trials.append(best_tr)
        # stage B: the most promising candidates are refitted together with the core parameters
        trials.sort(key=lambda t: t.sse_val)
        for i, tr in enumerate(trials[: max(int(refine), 0)]):
            # the leader, and whoever comes close to it (within a factor 1.5 in validation SSE)
            if i > 0 and (tr.sse_val > 1.5 * trials[0].sse_val or tr.sse_val >= stage.sse_val * (1 - 1e-9)):
                continue
            try:
                trB = _run_trial(tr.base, tr.effect, data, val, core_r, a_fit_est, opts, refit_core=True,
                                 start=tr.effect_params)
            except (ConfigError, DataError, ValueError, np.linalg.LinAlgError):
                continue
            trB.seconds += tr.seconds
            if trB.sse_est <= tr.sse_est:
                trials[i] = trB
        if retest_left:  # issue 20: the effects that are on, their own parameters refitted (defaults.py)
            say(f"round {rnd + 1}: re-testing {', '.join(retest_left)}")
            trials += dflt.retest_trials(bases, retest_left, data, val, core_r, a_fit_est, opts)
        for tr in trials:
            n_eff = min(n_eff0, ft.effective_samples(val.y[skip:] - tr.yhat_val[skip:]))
            tr.p_value = significance(stage.sse_val, tr.sse_val, n_eff, tr.n_added)
            tr.gain = max(0.0, 1.0 - tr.nrmse_val / stage.nrmse_val) if stage.nrmse_val > 0 else 0.0
        if not trials:
            break
        n_c = len(trials)
        for tr in trials:
            tr.significant = bool(tr.p_value < alpha / n_c and tr.gain >= min_rel_gain)
            if tr.significant and getattr(tr, "retest", False):
                tr.significant = dflt.attributable(tr, data, val, prior, n_eff0, alpha / n_c, min_rel_gain, skip)
        sig_ev = {tr.effect: ev.signature_evidence(twin.EFFECTS[tr.effect], a_val, twin, also=stage.analysis_est)
                  for tr in trials}
        trials.sort(key=lambda t: (t.significant, t.gain + 0.01 * sig_ev[t.effect]["score"] * t.gain), reverse=True)
        top = trials[0]
        # group what the data cannot tell apart
        n_eff_top = ft.effective_samples(val.y[skip:] - top.yhat_val[skip:])
        tol = 2.0 * math.sqrt(2.0 / max(n_eff_top, 1.0))
        e_rms_top = math.sqrt(top.sse_val / max(val.n - skip, 1))
        top_group = twin.EFFECTS[top.effect].group
        group = [top.effect]
        for tr in trials[1:]:
            # the data cannot tell tr from the leader when the leader's residual is not significantly smaller
            not_better = significance(tr.sse_val, top.sse_val, n_eff_top, 1) > alpha
            # a catalog ambiguity group: members that explain the data nearly as well (NRMSE within 2×) go together
            same_group = (bool(top_group) and twin.EFFECTS[tr.effect].group == top_group and tr.significant
                          and tr.nrmse_val <= 2.0 * top.nrmse_val)
            d_pred = float(np.sqrt(np.mean((tr.yhat_val[skip:] - top.yhat_val[skip:]) ** 2)))
            equal = tr.significant and (tr.sse_val <= top.sse_val * (1 + tol) or not_better) and d_pred < 0.5 * e_rms_top
            if same_group or equal:
                group.append(tr.effect)
        g1 = top.gain
        g2 = max([t.gain for t in trials if t.effect not in group] + [0.0])
        rows = []
        for tr in trials:
            s = sig_ev[tr.effect]
            if tr.effect in group:
                sep = 1.0 - (g2 / g1 if g1 > 0 else 1.0)
                conf = (1 - tr.p_value) * (0.5 + 0.5 * math.sqrt(max(sep, 0.0))) * (0.8 + 0.2 * s["score"])
                if tr.effect != top.effect:
                    conf *= (tr.gain / g1) if g1 > 0 else 0.0
            else:
                conf = (1 - tr.p_value) * 0.5 * ((tr.gain / g1) if g1 > 0 else 0.0) * (0.8 + 0.2 * s["score"])
            conf = float(min(1.0, max(0.0, conf))) if tr.significant else float(min(0.2, max(0.0, conf)) * 0.5)
            rows.append({"effect": tr.effect, "family": s["family"], "significant": tr.significant,
                         "retest": bool(getattr(tr, "retest", False)),
                         "confidence": conf, "signature_score": s["score"], "signature": s["text"],
                         "nrmse_val": tr.nrmse_val, "r2_val": tr.r2_val, "gain": tr.gain, "p_value": tr.p_value,
                         "params": tr.effect_params, "stderr": tr.stderr, "seconds": tr.seconds})
        round_info = {"round": rnd + 1, "nrmse_val_before": stage.nrmse_val, "n_eff": n_eff0, "candidates": rows,
                      "group": group}
        rounds.append(round_info)
        if not top.significant:
            break
        row = rows[0]
        fams = [ev.family_of(twin.EFFECTS[g]) for g in group]
        text = (f"{row['signature']}; adding {top.effect} and fitting "
                f"{_fmt_params(top.effect_params) or 'the core'} lowers the "
                f"validation NRMSE {stage.nrmse_val:.4g} → {top.nrmse_val:.4g} (F-test p = {top.p_value:.2g})")
        cause = {"effect": top.effect, "confidence": row["confidence"], "evidence": text,
                 "params": dict(top.effect_params), "stderr": dict(top.stderr), "family": row["family"],
                 "round": rnd + 1, "nrmse_val_before": stage.nrmse_val, "nrmse_val_after": top.nrmse_val,
                 "p_value": top.p_value}
        if getattr(top, "retest", False):
            cause.update(dflt.cause_fields(top, stage.nrmse_val, prior))
            retest_left.remove(top.effect)
        if len(group) > 1:
            cause["group"] = group
            cause["separate_by"] = ev.separating_experiment(fams)
            gains_txt = ", ".join(f"{r['gain']:.3f}" for r in rows if r["effect"] in group)
            cause["evidence"] += (f"; the data cannot tell {', '.join(group)} apart "
                                  f"(gains {gains_txt}); "
                                  f"to separate them: {cause['separate_by']}")
        causes.append(cause)
        stage = _stage(top.twin, data, val, opts)

    # quantisation: no prediction can follow it, the evidence is the lattice of the measured values
    for e in [c for c in (candidates if candidates is not None else twin.EFFECTS)
              if c in twin.EFFECTS and c not in twin.effects and ev.family_of(twin.EFFECTS[c]) == "quantization"]:
        q = ft.quantization_step(np.concatenate([data.y, val.y]))
        s = ev.signature_evidence(twin.EFFECTS[e], {"quantization": q}, twin)
        if q.get("p_value", 1.0) < alpha * 1e-3 and s["score"] > 0.3:
            causes.append({"effect": e, "confidence": float(s["score"]), "params": _quant_params(twin, e, q["step"]),
                           "evidence": (s["text"] + "; quantisation error depends on the noise, so adding it cannot "
                                        "lower the residual (no validation gain expected)"),
                           "family": "quantization", "round": 0})

    # what no catalog entry explains
    e_est = data.y - stage.yhat_est
    e_val = val.y - stage.yhat_val
    gen = _generic_residual_model(data, val, e_est, e_val, generic_lags, skip)
    gen_sig = bool(gen["p_value"] < alpha and (1.0 - gen["nrmse_ratio"]) >= max(5 * min_rel_gain, 0.02))
    unexplained = {"significant": gen_sig, **gen, "description": ev.describe_generic(stage.analysis_val)}
    if gen_sig:
        causes.append({"effect": "unexplained", "confidence": float(1 - gen["p_value"]) * 0.5,
                       "evidence": ("structure no catalog effect explains: a generic residual model (FIR of u, u², u³ "
                                    f"and a trend) removes {100 * (1 - gen['nrmse_ratio'] ** 2):.0f} % of the validation "
                                    f"residual variance; {unexplained['description']}"),
                       "params": {}})
    causes.sort(key=lambda c: -float(c["confidence"]))  # strongest first (stable: round order among equals)
    # issue 20: the residual against the noise measured from the data; parameters at a bound (realdata.py)
    verdict, beyond, at_bound = realdata.final_verdict(data, val, stage.yhat_val, causes, stage.twin, calib_info, skip)
    say(f"verdict {verdict}")
    kept_unpredictable = set(twin.effects) & _unpredictable(twin)  # noise/quantisation as configured
    out = {
        "verdict": verdict,
        "causes": causes,
        "baseline": base.summary(kept_unpredictable),
        "extended": stage.summary(kept_unpredictable),
        "gain": {"nrmse_ratio": stage.nrmse_val / base.nrmse_val if base.nrmse_val > 0 else 1.0,
                 "r2_delta": stage.r2_val - base.r2_val},
        "twin": twin.name,
        "calibration": calib_info,
        "saturation": saturation,
        "params_final": dataclasses.asdict(stage.twin.params),
        "rounds": rounds,
        "unexplained": unexplained,
        "residual_vs_noise": beyond,
        "split": split_info,
        "ranges": range_notes,
        "defaults": dflt.contributions(stage.twin, retest, data, val, skip),
        "at_bound": at_bound,
        "analysis": {"baseline": {"estimation": _public(base.analysis_est), "validation": _public(base.analysis_val)},
                     "extended": {"estimation": _public(stage.analysis_est), "validation": _public(stage.analysis_val)}},
        "seconds": time.perf_counter() - t_start,
    }
    if keep_stages:
        out["_stages"] = {"baseline": base, "extended": stage, "est": data, "val": val}
    return out


def _quant_params(twin: Twin, effect: str, step: float) -> dict[str, float]:
    """Parameters of a quantisation effect from the measured lattice step: the step itself, or the bit count
    that gives it over the configured range (LSB = 2·range/2^bits)."""
    fields = list(twin.EFFECTS[effect].params.values())
    bits = [f for f in fields if "bit" in f.lower()]
    rng = [f for f in fields if "range" in f.lower()]
    if bits and rng:
        r = float(getattr(twin.params, rng[0]))
        return {bits[0]: float(np.log2(2 * r / step)), rng[0]: r}
    floats = [f for f in fields if isinstance(getattr(twin.params, f, None), float)]
    return {floats[0]: float(step)} if floats else {}


def _fmt_params(p: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v:.4g}" if isinstance(v, (int, float)) else f"{k}={v}" for k, v in p.items())


def _public(a: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in a.items() if not k.startswith("_")}
