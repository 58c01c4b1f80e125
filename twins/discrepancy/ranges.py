"""Ranges from the data: the twin's amplitude limit, time constants and integration step
follow the record, and fitted parameters that end at a bound are reported and retried once with the bound
widened.

:func:`follow_record` (before the diagnosis calibrates anything):

- **amplitude**: where max|u| exceeds the twin's amplitude option (:data:`AMPLITUDE_OPTIONS`, for the
  cantilever ``amp_limit_v``, and ``pi_r_max_v`` with the Prandtl–Ishlinskii operator) the option is raised
  to max|u| (the data come from a different amplifier; otherwise the twin clips the measured input). When
  max|u| is beyond the option's documented range a DataError names the option and the largest value it
  takes.
- **time constants**: with creep on, the Kelvin–Voigt chain τ_i = τ₁·10^(i−1) gets enough elements
  (≤ 8, the documented maximum) for its longest time constant to reach the record's duration (a chain
  that stops at 100 s cannot follow a creep record of minutes).
- **a twin's own rule**: a twin with a ``follow_records(est, val) -> (twin, notes)`` method (the generic
  effects' ranges of :class:`twins.external.ExternalTwin`) applies it.
- **integration step**: :func:`twins.cantilever.substep.choose_substep` (bandwidth- and mode-chosen;
  only when ``max_substep_s`` is the default, a value the user set is kept); :func:`substep_for` re-chooses
  it (only finer) for each configuration the diagnosis adopts, since the calibrated hysteresis or an added
  asymmetry can need a finer step than the starting twin.

:func:`at_bounds` lists fitted parameters within 1 % (of the range width) of a bound; :func:`widened` returns
the twin with those bounds widened once (×10 away from zero for a positive range, by the range width
otherwise), so that the diagnosis can refit before it states a verdict. Dimensionless shares and ratios
(unit "1") are not widened: their ranges are physical (a share above 1 has no meaning).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import DataError
from twins.base import Twin, param_info
from twins.paramfields import with_ranges

__all__ = ["AMPLITUDE_OPTIONS", "follow_record", "substep_followed", "substep_for", "at_bounds", "widened", "BOUND_TOL"]

#: twin → parameters that must reach max|u| [V] (the second only for the PI operator)
AMPLITUDE_OPTIONS: dict[str, tuple[str, ...]] = {"cantilever": ("amp_limit_v", "pi_r_max_v")}
#: a parameter within this fraction of its range width from a bound is "at bound"
BOUND_TOL = 0.01


def follow_record(twin: Twin, est: Record, val: Record) -> tuple[Twin, list[str]]:
    """``twin`` adjusted to the records (see the module docstring) and one note per adjustment."""
    notes: list[str] = []
    info = param_info(type(twin.params))
    umax = max(float(np.max(np.abs(est.u))), float(np.max(np.abs(val.u))))
    changes: dict[str, Any] = {}
    for opt in AMPLITUDE_OPTIONS.get(twin.name, ()):
        if opt not in info:
            continue
        if opt == "pi_r_max_v" and getattr(twin.params, "hysteresis", "") != "prandtl-ishlinskii":
            continue
        cur = float(getattr(twin.params, opt))
        if umax > cur:
            hi = info[opt].range[1]
            if hi is not None and umax > float(hi):
                raise DataError(
                    f"the input reaches |u| = {umax:g} {est.units.get('u', 'V')}, above the largest "
                    f"{opt} the {twin.name} twin takes ({float(hi):g} {info[opt].unit}); scale the "
                    f"record or set {opt} (--set {opt}=...) within its range"
                )
            changes[opt] = umax
            notes.append(
                f"{opt} raised {cur:g} -> {umax:g} {info[opt].unit} (the input exceeds it; --set {opt}=... overrides)"
            )
    duration = (len(est) + len(val)) / est.fs
    if twin.has("creep") and "creep_elements" in info and "creep_tau_min_s" in info:
        n = int(twin.params.creep_elements)
        tau1 = float(twin.params.creep_tau_min_s)
        n_max = int(info["creep_elements"].range[1] or n)
        need = int(math.ceil(math.log10(max(duration / tau1, 1.0)))) + 1
        if need > n:
            n_new = min(need, n_max)
            if n_new > n:
                changes["creep_elements"] = n_new
                notes.append(
                    f"creep_elements {n} -> {n_new}: longest creep time constant "
                    f"{tau1 * 10 ** (n_new - 1):g} s for a {duration:.4g} s record"
                )
    tw = twin.with_params(**changes) if changes else twin
    follow = getattr(tw, "follow_records", None)  # a twin whose own ranges follow the data (twins.external)
    if callable(follow):
        tw, more = follow(est, val)
        notes += more
    if substep_followed(twin) and twin.name == "cantilever":
        cur = float(tw.params.max_substep_s)
        h = _chosen_substep(tw, est, val)
        if h > cur * (1 + 1e-9):
            tw = tw.with_params(max_substep_s=h)
            steps = tw.substeps(est.fs)  # type: ignore[attr-defined]  # substep_followed: a cantilever twin
            notes.append(
                f"max_substep_s {cur:g} -> {h:.3g} s: {steps} sub-steps per sample "
                "suffice for this record's bandwidth (FOH error bound ≤ 1e-4 of the span)"
            )
    return tw, notes


def substep_followed(twin: Twin) -> bool:
    """The twin's integration sub-step is chosen from the records (a cantilever at the default ``max_substep_s``;
    a value the user set is kept)."""
    if callable(getattr(twin, "finer_step", None)):  # a twin that re-chooses its own step (twins.equations)
        return True
    info = param_info(type(twin.params))
    return (
        twin.name == "cantilever"
        and "max_substep_s" in info
        and float(twin.params.max_substep_s) == float(info["max_substep_s"].default)
    )


def _chosen_substep(twin: Twin, est: Record, val: Record) -> float:
    """:func:`twins.cantilever.substep.choose_substep` for ``twin`` at its default sub-step, over both records."""
    from twins.cantilever.substep import choose_substep

    info = param_info(type(twin.params))
    base = twin.with_params(max_substep_s=float(info["max_substep_s"].default))
    u_all = np.concatenate([np.asarray(est.u, float), np.asarray(val.u, float)])
    return choose_substep(base, u_all, est.fs)


def substep_for(twin: Twin, est: Record, val: Record) -> Twin:
    """``twin`` with its sub-step made finer where its present configuration needs it.

    The sub-step is chosen once from the starting configuration; the bound depends on the hysteresis curvature
    (Bouc–Wen α, β, γ as calibrated, an added asymmetry), so a configuration the diagnosis adopts gets it
    re-chosen. Only finer: a configuration that drops an effect keeps the step it had."""
    own = getattr(twin, "finer_step", None)
    if callable(own):
        return own(est, val)
    if twin.name != "cantilever":
        return twin
    cur = float(twin.params.max_substep_s)
    h = _chosen_substep(twin, est, val)
    return twin.with_params(max_substep_s=h) if h < cur * (1 - 1e-9) else twin


def at_bounds(twin: Twin, names: Iterable[str], tol: float = BOUND_TOL) -> list[dict[str, Any]]:
    """Parameters of ``names`` whose value lies within ``tol`` of the range width from a documented bound."""
    info = param_info(type(twin.params))
    out = []
    for n in names:
        if n not in info:
            continue
        v = getattr(twin.params, n)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            continue
        lo, hi = info[n].range
        if lo is None or hi is None or not float(hi) > float(lo):
            continue
        side = bound_side(float(v), float(lo), float(hi), tol)
        if side is not None:
            out.append(
                {
                    "param": n,
                    "value": float(v),
                    "bound": float(lo) if side == "lower" else float(hi),
                    "side": side,
                    "unit": info[n].unit,
                }
            )
    return out


def bound_side(v: float, lo: float, hi: float, tol: float = BOUND_TOL) -> str | None:
    """``"lower"`` / ``"upper"`` when ``v`` lies within ``tol`` of the range width from that bound of [lo, hi]
    (in log units for a positive range spanning more than 30×), else None."""
    if lo > 0 and hi / lo > 30:  # log-scaled range: closeness in log units
        x, a, b = math.log(max(v, 1e-300)), math.log(lo), math.log(hi)
        near_lo, near_hi = x - a <= tol * (b - a), b - x <= tol * (b - a)
    else:
        near_lo, near_hi = v - lo <= tol * (hi - lo), hi - v <= tol * (hi - lo)
    return "lower" if near_lo else ("upper" if near_hi else None)


def widened(twin: Twin, hits: list[dict[str, Any]]) -> tuple[Twin, list[dict[str, Any]]]:
    """``twin`` with the ranges of ``hits`` widened once (module docstring); returns (twin, widened rows)."""
    info = param_info(type(twin.params))
    new_ranges: dict[str, tuple[float, float]] = {}
    rows = []
    for h in hits:
        n = h["param"]
        if info[n].unit in ("1", "") or n in new_ranges:
            continue
        lo, hi = info[n].bounds()
        if lo > 0:
            lo2, hi2 = (lo / 10.0, hi) if h["side"] == "lower" else (lo, hi * 10.0)
        else:
            w = hi - lo
            lo2, hi2 = (lo - w, hi) if h["side"] == "lower" else (lo, hi + w)
        new_ranges[n] = (lo2, hi2)
        rows.append({**h, "widened_to": [lo2, hi2]})
    if not new_ranges:
        return twin, []
    params = with_ranges(twin.params, new_ranges, "ranges widened")
    return type(twin)(params, twin.effects, twin.seed), rows


def bound_text(rows: list[dict[str, Any]]) -> str:
    """ "f1_hz=3000 Hz at its upper bound 3000" lines joined (for messages)."""
    return "; ".join(
        f"{r['param']}={r['value']:.4g} {r['unit']} at its {r['side']} bound {r['bound']:g}"
        + (
            f" (refitted with the range widened to [{r['widened_to'][0]:g}, {r['widened_to'][1]:g}])"
            if "widened_to" in r
            else ""
        )
        for r in rows
    )
