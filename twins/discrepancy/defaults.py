"""Re-test the effects that are already on (issue 20, item 1).

A twin's default effects (for the cantilever: creep, second mode, sensor low-pass) are part of the
configuration, so the add-an-effect loop of :mod:`.diagnose` never tries them. When the data have one of them
at another size (a PZT stack creeping three times faster than the default rate, a slower sensor) the baseline
absorbs what it can in the core parameters and the rest stays in the residual, unnamed.

For every deterministic effect that is on, with its own continuous parameters P_e (integers such as the
number of creep elements are structural and kept):

1. **refit**: P_e (pre-scanned over their documented ranges, then least squares) together with the core
   calibration parameters (:func:`.diagnose._run_trial` with the effect already present), from two starts:
   the calibrated core (calibrated with P_e at their configured values, it may have bent to mimic the
   mis-sized effect: a 3× creep rate on steps pulls the gain to 2.6× its value) and the core as configured;
   the one with the smaller estimation SSE is kept;
2. **removed**: the effect switched off and the core refitted (the effect's contribution is the validation
   NRMSE with it removed against the refit).

A refit whose validation gain passes the diagnosis' significance rule (F-test with p = |P_e| added
parameters, Bonferroni over the effects re-tested, and the relative-gain floor) — both against the baseline
and against the refitted twin with P_e put back at their configured values (so that a better core optimum
found on the way is not credited to the effect: nothing is named then) — is a cause of kind
``mis-sized default`` with its corrected parameters and their ratio to the configured values, e.g.
"creep: creep_per_decade 3.02× the configured 0.015, gain 41 % NRMSE"; it is ranked with the added effects
(confidence ``(1 − p)·(0.8 + 0.2·min(1, 10·gain))``) and the diagnosis continues from the refitted twin.
Effects are re-tested greedily: the best significant refit is kept, the others are re-tested from it.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from sysid.errors import ConfigError, DataError
from sysid.metrics import nrmse
from sysid.record import Record
from twins.base import Twin
from twins.calibration import calibrate as ls_calibrate

from . import features as ft

__all__ = ["retestable", "owned_fields", "retest_defaults"]


def retestable(twin: Twin, unpredictable: set[str], noise: Sequence[str]) -> list[str]:
    """Effects that are on and deterministic (noise and quantisation are judged by their signature only)."""
    return [e for e in twin.EFFECTS if e in twin.effects and e not in unpredictable and e not in noise]


def owned_fields(twin: Twin, effects: Sequence[str]) -> set[str]:
    """Parameter fields that belong to ``effects`` (held at their configured values in the baseline fit)."""
    out: set[str] = set()
    for e in effects:
        out.update(twin.EFFECTS[e].params.values())
    return out


def retest_defaults(stage, est: Record, val: Record, core: list[str], analysis: dict[str, Any],
                    opts: dict[str, Any], effects: Sequence[str], alpha: float, min_rel_gain: float,
                    configured: Twin, make_stage) -> tuple[Any, list[dict[str, Any]], list[dict[str, Any]]]:
    """Greedy re-test of ``effects`` from ``stage`` (module docstring). Returns (final stage, causes, rows)."""
    from .diagnose import _core_for, _int_fields, _numeric_fields, _run_trial, _simulate_val, _sse, significance

    skip = opts["skip"]
    causes: list[dict[str, Any]] = []
    rows: list[dict[str, Any]] = []
    todo = [e for e in effects]
    n_tests = max(len(todo), 1)
    seen: dict[str, dict[str, Any]] = {}  # contribution of each effect, measured once (first pass)
    while todo:
        trials = []
        for e in todo:
            fields = [f for f in _numeric_fields(stage.twin, stage.twin.EFFECTS[e].params.values())
                      if f not in _int_fields(stage.twin, stage.twin.EFFECTS[e].params.values())]
            if not fields:
                continue
            # two starts, as for added effects: the calibrated core (which may have bent to mimic the mis-sized
            # effect) and the core as configured
            starts = [stage.twin, stage.twin.with_params(**{c: getattr(configured.params, c) for c in _core_for(
                stage.twin, core) if c not in fields})]
            tr = None
            for b in starts:
                try:
                    t = _run_trial(b, e, est, val, core, analysis, opts, refit_core=True)
                except (ConfigError, DataError, ValueError, np.linalg.LinAlgError) as exc:
                    rows.append({"effect": e, "error": str(exc)})
                    continue
                if tr is None or t.sse_est < tr.sse_est:
                    tr = t
            if tr is None:
                continue
            n_eff = min(ft.effective_samples(val.y[skip:] - stage.yhat_val[skip:]),
                        ft.effective_samples(val.y[skip:] - tr.yhat_val[skip:]))
            tr.p_value = significance(stage.sse_val, tr.sse_val, n_eff, tr.n_added)
            tr.gain = max(0.0, 1.0 - tr.nrmse_val / stage.nrmse_val) if stage.nrmse_val > 0 else 0.0
            tr.significant = bool(tr.p_value < alpha / n_tests and tr.gain >= min_rel_gain)
            if tr.significant:
                # the gain must come from the effect's own parameters, not from a better core optimum: the refitted
                # twin with P_e put back at their configured values must be significantly worse
                yv0 = _simulate_val(tr.twin.with_params(**{f: getattr(configured.params, f) for f in fields}), est, val)
                sse0 = _sse(val.y, yv0, skip)
                p0 = significance(sse0, tr.sse_val, n_eff, tr.n_added)
                g0 = 1.0 - math.sqrt(tr.sse_val / sse0) if sse0 > 0 and math.isfinite(sse0) else 0.0
                if not (p0 < alpha / n_tests and g0 >= min_rel_gain):
                    tr.significant = False
                    tr.core_only = True
            trials.append((e, fields, tr))
        if not trials:
            break
        trials.sort(key=lambda x: (x[2].significant, x[2].gain), reverse=True)
        for e, fields, tr in trials:
            ratios = {f: _ratio(tr.effect_params.get(f), getattr(configured.params, f, None)) for f in fields}
            row = {"effect": e, "kind": "default re-test", "significant": tr.significant, "gain": tr.gain,
                   "p_value": tr.p_value, "nrmse_val_before": stage.nrmse_val, "nrmse_val": tr.nrmse_val,
                   "params": dict(tr.effect_params), "configured": {f: getattr(configured.params, f) for f in fields},
                   "ratio": ratios,
                   "contribution": (_contribution(tr, e, est, val, core, opts) if e not in seen else seen[e])}
            seen[e] = row["contribution"]
            rows.append(row)
        e, fields, top = trials[0]
        if not top.significant:
            break
        row = next(r for r in reversed(rows) if r["effect"] == e)
        changed = [f for f in fields if abs(math.log(max(row["ratio"][f], 1e-300))) > math.log(1.05)] or fields
        size = ", ".join(f"{f} {row['ratio'][f]:.3g}× the configured {row['configured'][f]:.4g}" for f in changed)
        text = (f"{e}: {size}, gain {100 * top.gain:.0f} % NRMSE (validation NRMSE {stage.nrmse_val:.4g} → "
                f"{top.nrmse_val:.4g}, F-test p = {top.p_value:.2g})")
        contrib = row["contribution"]
        if contrib.get("nrmse_val_removed") is not None:
            text += (f"; without {e} the refitted core reaches NRMSE {contrib['nrmse_val_removed']:.4g} "
                     f"(its contribution: {100 * contrib['share']:.0f} % of that NRMSE)")
        causes.append({"effect": e, "kind": "mis-sized default", "confidence": _confidence(top.p_value, top.gain),
                       "evidence": text, "params": dict(top.effect_params), "stderr": dict(top.stderr),
                       "ratio_to_configured": row["ratio"], "family": "default", "round": 0,
                       "gain": top.gain, "nrmse_val_before": stage.nrmse_val, "nrmse_val_after": top.nrmse_val,
                       "p_value": top.p_value})
        stage = make_stage(top.twin)
        todo = [x for x in todo if x != e]
    return stage, causes, rows


def _ratio(v, v0) -> float:
    try:
        v, v0 = float(v), float(v0)
    except (TypeError, ValueError):
        return float("nan")
    return v / v0 if v0 != 0 else float("inf")


def _confidence(p: float, gain: float) -> float:
    return float(min(1.0, max(0.0, (1.0 - p) * (0.8 + 0.2 * min(1.0, 10.0 * gain)))))


def _contribution(tr, effect: str, est: Record, val: Record, core: list[str], opts: dict[str, Any]) -> dict[str, Any]:
    """Validation NRMSE with ``effect`` removed and the core refitted (scan budget), and the effect's share
    ``1 − NRMSE_refit/NRMSE_removed`` of it."""
    from .diagnose import _core_for, _simulate, _simulate_val

    tw = tr.twin.with_effects(set(tr.twin.effects) - {effect})
    names = _core_for(tw, core)
    try:
        if names:
            tw = ls_calibrate(tw, est, names, simulate=_simulate, max_nfev=opts["scan_nfev"], skip=opts["skip"]).twin
        yv = _simulate_val(tw, est, val)
    except (ConfigError, DataError, ValueError, np.linalg.LinAlgError) as exc:
        return {"nrmse_val_removed": None, "error": str(exc)}
    if not np.all(np.isfinite(yv)):
        return {"nrmse_val_removed": None}
    n_rm = nrmse(val.y, yv, opts["skip"])
    return {"nrmse_val_removed": float(n_rm), "share": float(max(0.0, 1.0 - tr.nrmse_val / n_rm)) if n_rm > 0 else 0.0}
