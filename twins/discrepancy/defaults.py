"""Re-test the effects that are already on.

A twin's default effects (for the cantilever: creep, second mode, sensor low-pass) are part of the
configuration, so the add-an-effect loop of :mod:`.diagnose` never tried them. When the data have one of them
at another size (a PZT stack creeping three times faster than the default rate, a slower sensor) the baseline
absorbs what it can in the core parameters and the rest stays in the residual, unnamed.

The baseline is calibrated with the parameters P_e of every deterministic effect that is on held at their
configured values (integers such as the number of creep elements are structural and always kept). In every
round of the diagnosis each such effect not yet re-tested successfully is a candidate beside the effects that
could be added, with the same ranking, significance rule and grouping:

1. **refit**: P_e (pre-scanned over their documented ranges, then least squares) together with the core
   calibration parameters (:func:`.trials.run_trial` with the effect already present), from the round's
   starting points (the calibrated core, which may have bent to mimic the mis-sized effect — a 3× creep rate
   on steps pulls the gain to 2.6× its value — and the core as configured);
2. **attributable**: the gain must come from P_e, not from a better core optimum found on the way: the
   refitted twin with P_e put back at their configured values must be significantly worse (same F-test and
   relative-gain floor), else the re-test is not significant;
3. **removed**: the effect's contribution is the validation NRMSE of the current twin with the effect switched
   off (no refit), against the NRMSE with it (reported for every effect that is on, under ``defaults``).

A significant re-test is a cause of kind ``mis-sized default`` with its corrected parameters and their ratio
to the configured values, e.g. "creep: creep_per_decade 3× the configured 0.015, gain 99 % NRMSE".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from sysid.evaluation.metrics import nrmse
from twins.base import Twin

from .fields import choice_fields, effect_fields
from .options import DiagnoseOptions
from .prediction import significantly_better, simulate_val, sse
from .trials import Trial, run_trial

__all__ = ["retestable", "owned_fields", "retest_trials", "attributable", "holds", "cause_fields", "contributions"]


def retestable(twin: Twin, unpredictable: set[str], noise: Sequence[str]) -> list[str]:
    """Effects that are on and deterministic (noise and quantisation are judged by their signature only)."""
    return [e for e in twin.EFFECTS if e in twin.effects and e not in unpredictable and e not in noise]


def owned_fields(twin: Twin, effects: Sequence[str]) -> set[str]:
    """Parameter fields that belong to ``effects`` (held at their configured values in the baseline fit)."""
    out: set[str] = set()
    for e in effects:
        out.update(twin.EFFECTS[e].params.values())
    return out


def _fields(twin: Twin, effect: str) -> list[str]:
    return effect_fields(twin, twin.EFFECTS[effect].params.values())


def retest_trials(
    bases: Sequence[Twin],
    effects: Sequence[str],
    est: Record,
    val: Record,
    core: list[str],
    analysis: dict[str, Any],
    opts: DiagnoseOptions,
) -> list[Trial]:
    """One trial per effect of ``effects`` (P_e and the core refitted; the best of ``bases`` by estimation SSE),
    marked ``retest = True``."""
    out = []
    for e in effects:
        if not _fields(bases[0], e):
            continue
        best = None
        for b in bases:
            # a list-valued parameter (a model variant: Rapp or cubic compression) is part of the effect's family:
            # each variant is fitted and the best kept (run_trial's variant loop; a variant's fit counts one more
            # parameter), so a cubic compression is not forced into the configured Rapp curve
            try:
                t = run_trial(b, e, est, val, core, analysis, opts, refit_core=True)
            except (ConfigError, DataError, ValueError, np.linalg.LinAlgError):
                continue
            if best is None or t.sse_est < best.sse_est:
                best = t
        if best is not None:
            best.retest = True
            out.append(best)
    return out


def attributable(
    tr: Trial, est: Record, val: Record, configured: Twin, n_eff: float, level: float, min_rel_gain: float, skip: int
) -> bool:
    """Step 2 of the module docstring: P_e back at their configured values must be significantly worse."""
    return holds(tr.twin, tr.effect, tr.sse_val, tr.n_added, est, val, configured, n_eff, level, min_rel_gain, skip)


def holds(
    twin: Twin,
    effect: str,
    sse_val: float,
    n_added: int,
    est: Record,
    val: Record,
    configured: Twin,
    n_eff: float,
    level: float,
    min_rel_gain: float,
    skip: int,
) -> bool:
    """``twin`` (validation SSE ``sse_val``) with ``effect``'s parameters back at their configured values is
    significantly worse (F-test below ``level`` and a relative gain of at least ``min_rel_gain``)."""
    fields = _fields(configured, effect) + choice_fields(configured, configured.EFFECTS[effect].params.values())
    yv0 = simulate_val(twin.with_params(**{f: getattr(configured.params, f) for f in fields}), est, val)
    return significantly_better(sse(val.output, yv0, skip), sse_val, n_eff, n_added, level, min_rel_gain)


def cause_fields(tr: Trial, nrmse_before: float, configured: Twin) -> dict[str, Any]:
    """Kind, ratios to the configured values and the evidence sentence of a significant re-test."""
    fields = _fields(configured, tr.effect)
    ratio = {}
    for f in fields:
        v0 = float(getattr(configured.params, f))
        ratio[f] = float(tr.effect_params.get(f, v0)) / v0 if v0 != 0 else float("inf")
    changed = [f for f in fields if abs(math.log(max(ratio[f], 1e-300))) > math.log(1.05)] or fields
    size = ", ".join(f"{f} {ratio[f]:.3g}× the configured {float(getattr(configured.params, f)):.4g}" for f in changed)
    for c in choice_fields(configured, configured.EFFECTS[tr.effect].params.values()):
        if c in tr.effect_params and tr.effect_params[c] != getattr(configured.params, c):
            size += f", {c} {tr.effect_params[c]} instead of the configured {getattr(configured.params, c)}"
    text = (
        f"{tr.effect} (on by default) mis-sized: {size}, gain {100 * tr.gain:.0f} % NRMSE (validation NRMSE "
        f"{nrmse_before:.4g} → {tr.nrmse_val:.4g}, F-test p = {tr.p_value:.2g})"
    )
    return {
        "kind": "mis-sized default",
        "evidence": text,
        "ratio_to_configured": ratio,
        "family": "default",
        "gain": tr.gain,
    }


def contributions(twin: Twin, effects: Sequence[str], est: Record, val: Record, skip: int) -> list[dict[str, Any]]:
    """Step 3: validation NRMSE of ``twin`` with and without each effect of ``effects`` (no refit)."""
    y_with = simulate_val(twin, est, val)
    n_with = nrmse(val.y, y_with, skip)
    out = []
    for e in effects:
        if e not in twin.effects:
            continue
        try:
            y_wo = simulate_val(twin.with_effects(set(twin.effects) - {e}), est, val)
        except (ConfigError, DataError, ValueError):
            continue
        n_wo = nrmse(val.y, y_wo, skip)
        out.append(
            {
                "effect": e,
                "nrmse_val": float(n_with),
                "nrmse_val_removed": float(n_wo),
                "share": float(max(0.0, 1.0 - n_with / n_wo)) if n_wo > 0 else 0.0,
                "params": {f: getattr(twin.params, f) for f in _fields(twin, e)},
            }
        )
    return out
