"""The prediction a diagnosis compares with the data, and the numbers it is judged by.

The prediction is the twin's deterministic free-run simulation: without the effects that add error no
prediction can follow (noise, quantisation), clipped to the saturation rails of the measured record when it
has any, and for a validation record that continues the estimation record simulated as that continuation.
:func:`significance` is the F-test every gain of the diagnosis is judged by.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats

from sysid.data.record import Record
from twins.base import Twin
from twins.calibration import calibrate

from . import evidence as ev
from .features import clip_to_rails

__all__ = [
    "NOISE_EFFECTS",
    "unpredictable",
    "deterministic",
    "simulate",
    "simulate_val",
    "with_rails",
    "sse",
    "significance",
    "significantly_better",
    "continues",
    "INITIAL_KEY",
    "validation_start",
    "MIN_SCORED_SAMPLES",
]

#: effects that model unpredictable noise: never a candidate cause, always off in the fitted prediction
NOISE_EFFECTS: tuple[str, ...] = ("measurement_noise",)

#: meta key under which the diagnosis attaches the saturation rails to its working copies of the records
RAILS_KEY = "diagnose_saturation_rails"
#: meta key of a separate validation record's own start state (the twin's ``INITIAL_CONDITION_PARAMS``, set by
#: :func:`validation_start`): every prediction of the record starts there
INITIAL_KEY = "diagnose_initial_conditions"

#: fewest samples after skip that a diagnosis scores: residual gradients, spectra and correlation lags need a record
MIN_SCORED_SAMPLES = 32


def unpredictable(twin: Twin) -> set[str]:
    """Effects that add error no prediction can follow: noise, and quantisation (its error depends on the
    noise); they are left out of the fitted prediction and are judged by their data signature only."""
    return {e for e, s in twin.EFFECTS.items() if e in NOISE_EFFECTS or ev.family_of(s) in ("noise", "quantization")}


def deterministic(twin: Twin) -> Twin:
    """The same twin without its noise and quantisation effects (the prediction to compare with data)."""
    eff = set(twin.effects) - unpredictable(twin)
    return twin if eff == set(twin.effects) else twin.with_effects(eff)


def simulate(twin: Twin, rec: Record) -> np.ndarray:
    """The twin's output for ``rec.u``, clipped to the record's saturation rails when it has any."""
    return clip_to_rails(np.asarray(twin.simulate(rec.u, rec.fs), dtype=float), rec.meta.get(RAILS_KEY))


def with_rails(rec: Record, rails: dict[str, Any]) -> Record:
    """``rec`` carrying the saturation rails ``rails`` (unchanged when neither side has one)."""
    if rails.get("lo") is None and rails.get("hi") is None:
        return rec
    return rec.replace(meta={**rec.meta, RAILS_KEY: {"lo": rails["lo"], "hi": rails["hi"]}})


def continues(est: Record, val: Record) -> bool:
    """True when ``val`` directly continues ``est`` (same source and fs, ``t0`` at the end of ``est``, as
    ``Record.split`` makes them): the validation is then simulated as the continuation of the estimation input
    (still free run, no measured output used), so a system with memory (hysteresis, creep) is not restarted."""
    if val.fs != est.fs or "t0" not in val.meta or est.source != val.source:
        return False
    t_end = float(est.meta.get("t0", 0.0)) + len(est) / est.fs
    return abs(float(val.meta["t0"]) - t_end) < 0.5 / est.fs


def simulate_val(twin: Twin, est: Record, val: Record) -> np.ndarray:
    """The prediction of the validation record: the continuation of ``est`` where it continues it, else a
    simulation from the record's own start state where the diagnosis set one (``INITIAL_KEY``) — a
    start state is a property of a record, not of the system, and one fitted on the estimation record does not
    carry to a separate experiment."""
    if continues(est, val):
        y = simulate(twin, Record(u=np.concatenate([est.u, val.u]), y=None, fs=est.fs))[len(est) :]
        return clip_to_rails(y, val.meta.get(RAILS_KEY))
    start = val.meta.get(INITIAL_KEY)
    return simulate(twin.with_params(**start) if start else twin, val)


def sse(y: np.ndarray, yh: np.ndarray, skip: int) -> float:
    """Sum of squared errors after the first ``skip`` samples (inf when not finite)."""
    r = np.asarray(y, float)[skip:] - np.asarray(yh, float)[skip:]
    v = float(np.sum(r * r))
    return v if math.isfinite(v) else float("inf")


def significance(sse0: float, sse1: float, n_eff: float, p_extra: int, p_total: int | None = None) -> float:
    """p-value of the F-test of nested models that the residual variance fell from sse0 to sse1 by adding
    ``p_extra`` = k parameters to a model that then fits ``p_total`` = k_total in all (default k), with
    ``n_eff`` effective independent samples: ``F = (N_eff − k_total)/k · (s₀² − s₁²)/s₁²`` on (k, N_eff − k_total)
    degrees of freedom. A richer family (larger k) needs a larger fall to be significant: under the null
    hypothesis (the extra parameters fit noise only) F follows the F distribution and p is uniform."""
    p = max(int(p_extra), 1)
    if not (math.isfinite(sse0) and math.isfinite(sse1)) or sse1 >= sse0 or sse1 <= 0:
        return 1.0 if sse1 > 0 or sse1 >= sse0 else 0.0
    d2 = max(n_eff - max(int(p_total) if p_total is not None else p, p), 1.0)
    F = d2 / p * (sse0 - sse1) / sse1
    return float(stats.f.sf(F, p, d2))


def significantly_better(sse0: float, sse1: float, n_eff: float, k: int, level: float, min_rel_gain: float) -> bool:
    """A fit of validation SSE ``sse1`` is significantly better than a reference of ``sse0`` (F-test of
    :func:`significance` below ``level`` with ``k`` added parameters, and a relative NRMSE gain of at least
    ``min_rel_gain``); a reference that is not finite or is exact counts as beaten."""
    if not (math.isfinite(sse0) and sse0 > 0):
        return True
    return bool(significance(sse0, sse1, n_eff, k) < level and 1.0 - math.sqrt(sse1 / sse0) >= min_rel_gain)


def validation_start(
    twin: Twin, given: Twin, est: Record, val: Record, core: list[str], how: str, skip: int
) -> tuple[Record, dict[str, float] | None]:
    """The validation record with the state it starts in attached (:data:`INITIAL_KEY`), and that state: the
    calibrated ``twin``'s ``INITIAL_CONDITION_PARAMS`` among the calibrated ``core`` (none: the record unchanged).

    A start state is the rig's history before a record, not a property of the system. ``how``: ``"given"`` the
    configuration's (``given``) — a prediction of the record that uses none of its data; ``"fitted"`` fitted on
    the record (as MATLAB's ``compare`` estimates x0), for records that start in unknown states — it also takes up
    level differences between the records, which a drift is judged by; ``"estimation"`` the estimation record's
    fitted start, carried over: one read from that record's first samples (coloured noise, another record's
    history) offsets the whole validation record, and a trial that mends the offset is named for it."""
    names = [n for n in type(twin).INITIAL_CONDITION_PARAMS if n in core]
    if not names or continues(est, val) or how == "estimation":
        return val, None
    if how == "fitted":
        fit = calibrate(twin, val, names, simulate=simulate, skip=skip).twin
        better = sse(val.output, simulate(fit, val), skip) < sse(val.output, simulate(twin, val), skip)
        start = {n: float(getattr((fit if better else twin).params, n)) for n in names}
    else:
        start = {n: float(getattr(given.params, n)) for n in names}
    return val.replace(meta={**val.meta, INITIAL_KEY: start}), start
