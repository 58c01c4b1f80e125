"""Trial fits of catalog effects, and the stages (configurations with their residual analysis) between them.

A trial adds one effect to a configuration and fits it to the estimation record: stage A fits the effect's
own parameters after a pre-scan (:mod:`.prescan`) with the core held at its calibration; stage B also refits
the core. The validation record is simulated with the result; its SSE is what the ranking judges.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Iterable
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.evaluation.metrics import nrmse, r2
from twins.base import Twin, param_info
from twins.calibration import calibrate as ls_calibrate

from . import features as ft
from .fields import choice_fields, core_for, effect_fields, int_fields
from .options import DiagnoseOptions
from .prediction import simulate, simulate_val, sse
from .prescan import prescan

__all__ = ["Trial", "run_trial", "Stage", "make_stage"]


@dataclasses.dataclass
class Trial:
    """One candidate effect fitted: the twin with it, its parameters and the validation numbers."""

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
    base: Twin  # the configuration the effect was added to
    p_value: float = 1.0
    gain: float = 0.0
    significant: bool = False
    seconds: float = 0.0
    n_added: int = 0  # k: the effect's parameters the trial chose from the data (a variant choice counts one)
    n_total: int = 0  # k_total: every parameter the trial fitted (k and the core parameters refitted with them)
    retest: bool = False  # an effect that was already on, its own parameters refitted (:mod:`.defaults`)
    judged_samples: int = 0  # validation samples (after skip) its gain and p-value were judged on (:mod:`.ranking`)
    # validation SSE of the configuration with only its core refitted (None: not computed), the reference a trial
    # is tested against beside the stage (:func:`core_refit_sse`)
    ref_sse_val: float | None = None


def run_trial(
    base: Twin,
    effect: str,
    est: Record,
    val: Record,
    core: list[str],
    a_val: dict[str, Any],
    opts: DiagnoseOptions,
    refit_core: bool,
    start: dict[str, float] | None = None,
    choice: dict[str, Any] | None = None,
) -> Trial:
    """Add ``effect`` to ``base`` and fit it to ``est``: stage A (``refit_core=False``) fits the effect's own
    parameters after a pre-scan with the core held at its calibration; stage B also refits the core.

    An effect with both a list-valued parameter (a model variant, e.g. Rapp or cubic compression) and numeric
    ones is fitted once per variant (at most 8 combinations) and the variant with the smallest estimation SSE
    is kept: the variants are different structures, each with its own optimum of the numeric parameters
    (choosing the variant at the configured numeric values picks the wrong one when they are far off)."""
    t0 = time.perf_counter()
    spec = base.EFFECTS[effect]
    tw = base.with_effects(set(base.effects) | {effect})
    eff_fields = effect_fields(tw, spec.params.values())
    cat_fields = choice_fields(tw, spec.params.values())
    if start is None and choice is None and cat_fields and eff_fields:
        info = param_info(type(tw.params))
        best: Trial | None = None
        combos = list(itertools.islice(itertools.product(*(info[c].choices or () for c in cat_fields)), 8))
        for combo in combos:
            tr = run_trial(base, effect, est, val, core, a_val, opts, refit_core, choice=dict(zip(cat_fields, combo)))
            if best is None or tr.sse_est < best.sse_est:
                best = tr
        assert best is not None
        best.seconds = time.perf_counter() - t0
        if len(combos) > 1:  # the variant was chosen by the data too: one more degree of freedom
            best.n_added += 1
            best.n_total += 1
        return best
    if choice is not None:
        tw = tw.with_params(**choice)
        x0 = {**(prescan(tw, est, eff_fields, a_val, opts.scan_points, opts.skip, ()) if eff_fields else {}), **choice}
    elif start is None:
        own = getattr(tw, "start_values", None)  # a twin that finds its effects' starting values itself
        x0 = (own(effect, est, opts.skip) if callable(own) else None) or (
            prescan(tw, est, eff_fields, a_val, opts.scan_points, opts.skip, cat_fields)
            if (eff_fields or cat_fields)
            else {}
        )
    else:
        x0 = dict(start)
    return _fit(base, tw, effect, est, val, core, x0, eff_fields, cat_fields, opts, refit_core, t0, choice)


def _fit(
    base: Twin,
    tw: Twin,
    effect: str,
    est: Record,
    val: Record,
    core: list[str],
    x0: dict[str, Any],
    eff_fields: list[str],
    cat_fields: list[str],
    opts: DiagnoseOptions,
    refit_core: bool,
    t0: float,
    choice: dict[str, Any] | None = None,
) -> Trial:
    """Least squares from the start ``x0`` (categorical and integer parameters stay at their scanned values)."""
    fixed = {k: v for k, v in x0.items() if k in cat_fields or k in int_fields(tw, eff_fields)}
    # k: the numeric parameters fitted or scanned, and a list-valued one scanned here (a fluid) — not one fixed by
    # the caller (a variant the choice loop fits one at a time counts there, a re-test keeps its variant)
    k = len(eff_fields) + (len(cat_fields) if choice is None else 0)
    if fixed:
        tw = tw.with_params(**{k: (int(round(v)) if k not in cat_fields else v) for k, v in fixed.items()})
    x0 = {k: v for k, v in x0.items() if k not in fixed}
    names = [f for f in eff_fields if f not in fixed]
    n_core = 0
    if refit_core:
        core_names = [c for c in core_for(tw, core) if c not in eff_fields]
        names += core_names
        n_core = len(core_names)
    if names:
        fit_tw, fitted, stderr, ye = _least_squares(base, tw, est, core, x0, names, opts, refit_core)
    else:
        fit_tw, fitted, stderr = tw, {}, {}
        ye = simulate(fit_tw, est)
    yv = simulate_val(fit_tw, est, val)
    ok = bool(np.all(np.isfinite(yv)))
    eff_all = eff_fields + [c for c in cat_fields if c not in eff_fields]
    return Trial(
        effect=effect,
        twin=fit_tw,
        fitted=fitted,
        effect_params={f: fitted.get(f, getattr(fit_tw.params, f)) for f in eff_all},
        stderr={f: stderr.get(f, float("nan")) for f in eff_fields},
        sse_est=sse(est.output, ye, opts.skip),
        sse_val=sse(val.output, yv, opts.skip),
        yhat_val=yv,
        nrmse_val=nrmse(val.y, yv, opts.skip) if ok else float("inf"),
        r2_val=r2(val.y, yv, opts.skip) if ok else float("-inf"),
        seconds=time.perf_counter() - t0,
        n_added=max(k, 1),
        n_total=max(k, 1) + n_core,
        base=base,
    )


def _least_squares(
    base: Twin,
    tw: Twin,
    est: Record,
    core: list[str],
    x0: dict[str, Any],
    names: list[str],
    opts: DiagnoseOptions,
    refit_core: bool,
) -> tuple[Twin, dict[str, float], dict[str, float], np.ndarray]:
    """Least squares of ``names`` from ``x0``; never a worse estimation fit than the start.

    ``scipy.optimize.least_squares`` moves a start that lies on a bound strictly inside the bounds. For a
    parameter whose bound is a switch — a first-order low-pass whose cutoff 0 means "no filter"
    (``wall_echo_cutoff_hz``), where 10⁻³ Hz removes the whole path — that first move lands in a flat region
    where every neighbour has the path gone, and the fit stops there, worse than its start: the pre-scan had
    found the echo's delay and size with no filter (estimation SSE at the noise), and the fit returned an echo
    filtered away (gain 0; seed 3 of the outside-injected echo). So the start's SSE is compared with the fit's,
    and where the start is better the fit is run again with the parameters that start on a bound held there
    (the pre-scan chose that bound value over its grid); the better of the fits and the start is kept.

    That move is 10⁻¹⁰ of the value, and the trust-region steps that follow are cut short at the bound: a slow
    drift whose period started on its lower bound (its amplitudes at 0, the period's scan flat) moved its
    amplitudes by 10⁻⁵ of the drift in 15 evaluations (benchmark seed 515). A start on a bound is therefore moved
    inside by :data:`INSIDE` of the range first (:func:`_inside`); the comparison with the start on the bound
    stays."""
    start_vals = {**{c: float(getattr(base.params, c)) for c in core}, **x0}
    nfev = opts.trial_nfev if refit_core else opts.scan_nfev
    info = param_info(type(tw.params))
    on_bound = {
        f: float(start_vals[f]) for f in names if f in x0 and f in info and float(start_vals[f]) in tuple(info[f].range)
    }

    def run(t: Twin, fields: list[str]) -> tuple[Twin, dict[str, float], dict[str, float], np.ndarray]:
        x_in = {**start_vals, **{f: _inside(v, info[f].range) for f, v in on_bound.items() if f in fields}}
        res = ls_calibrate(t, est, fields, x0=x_in, simulate=simulate, max_nfev=nfev, skip=opts.skip)
        return res.twin, res.fitted, res.stderr, simulate(res.twin, est)

    out = run(tw, names)
    if not on_bound:
        return out
    t_start = tw.with_params(**{f: v for f, v in start_vals.items() if f in names})
    y_start = simulate(t_start, est)
    cost_fit, cost_start = sse(est.output, out[3], opts.skip), sse(est.output, y_start, opts.skip)
    if cost_fit <= cost_start:
        return out
    rest = [f for f in names if f not in on_bound]
    best = (t_start, {f: float(start_vals[f]) for f in names}, {f: float("nan") for f in names}, y_start)
    if rest:
        held = run(tw.with_params(**on_bound), rest)
        if sse(est.output, held[3], opts.skip) < cost_start:
            best = (held[0], {**on_bound, **held[1]}, {**{f: float("nan") for f in on_bound}, **held[2]}, held[3])
    return best


#: how far inside its range a start on a bound is moved before a fit, as a fraction of the range's width
INSIDE = 1e-4


def _inside(v: float, rng: tuple[float | None, float | None]) -> float:
    """``v`` (on a bound of ``rng``) moved inside by :data:`INSIDE` of the range's width."""
    if rng[0] is None or rng[1] is None:
        return v
    lo, hi = float(rng[0]), float(rng[1])
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        return v
    return lo + INSIDE * (hi - lo) if v <= lo else hi - INSIDE * (hi - lo)


def core_refit_sse(stage: Stage, est: Record, val: Record, core: list[str], opts: DiagnoseOptions) -> float | None:
    """Validation SSE of ``stage``'s configuration with its core parameters refitted alone, from the same start and
    with the same budget as a stage-B trial (None without a core to refit). A trial that refits the core beside its
    effect is nested in this fit, not in the calibration, and whatever the refit gains without any effect (a
    calibration short of its optimum) is not an effect's gain either: every trial is tested against the better of
    the two (conservative for a trial fitted with the core held)."""
    names = core_for(stage.twin, core)
    if not names:
        return None
    fit_tw, _, _, _ = _least_squares(stage.twin, stage.twin, est, core, {}, names, opts, refit_core=True)
    return sse(val.output, simulate_val(fit_tw, est, val), opts.skip)


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
        return {
            "effects": sorted(set(self.twin.effects) | set(also)),
            "r2_val": self.r2_val,
            "nrmse_val": self.nrmse_val,
            "tests": ft.tests_summary(self.analysis_val["_tests_full"]),
        }


def make_stage(twin: Twin, est: Record, val: Record, opts: DiagnoseOptions) -> Stage:
    """Simulate both records with ``twin`` and analyse both residuals."""
    ye = simulate(twin, est)
    yv = simulate_val(twin, est, val)
    ae = ft.analyse(est.u, est.output, ye, est.fs, est.meta, max_lag=opts.max_lag, max_echo_s=opts.max_echo_s)
    av = ft.analyse(val.u, val.output, yv, val.fs, val.meta, max_lag=opts.max_lag, max_echo_s=opts.max_echo_s)
    yval = val.output
    return Stage(twin, ye, yv, ae, av, nrmse(yval, yv, opts.skip), r2(yval, yv, opts.skip), sse(yval, yv, opts.skip))
