"""Does a named cause carry over from the estimation record to the validation record?

One physical mechanism has one set of parameters on one rig: the same limiter, echo path or delay in every record
(a drift, a function of each record's own time, excepted). The diagnosis fits a cause's parameters on the
estimation record and judges them on the validation record. A catalog effect that imitates a mechanism outside the
catalog — a delay or an echo for a backlash on the drive, a delay for a first-order lag — fits each record with
values that suit that record's excitation (a lag's equivalent delay depends on the frequencies driven, a play's on
the amplitude). Refitted on the validation record alone (the rest of the extended twin as fitted), its parameters
move and the validation residual falls; a right cause's refit fits little but noise. On the diagnosis benchmark's
313 cantilever and user-model cases (docs/discrepancy-notes.md, "a cause that does not carry over") the rule below
marks 5 of the 143 right names and 14 of the 58 wrong ones.

:func:`mark_untransferable` refits each named cause and marks one (``untransferable``: the fall, its p-value, the
parameters before and after) whose refit moves a parameter by at least :data:`MIN_MOVE` of its value and lowers
the validation residual power by at least :data:`MIN_DROP`, significantly (F-test on N_eff,
:func:`.prediction.significance`); its confidence is then capped at
:data:`twins.discrepancy.confidence.TRANSFER_CAP` (:func:`.confidence.calibrate_causes`). Not tested: effects whose
law depends on the record's time (``EffectSpec.time_varying``) and causes with no continuous parameter (a
quantiser's lattice).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from twins.base import Twin
from twins.calibration import calibrate
from twins.paramfields import param_info

from . import features as ft
from .fields import choice_fields, int_fields
from .prediction import significance, simulate_val, sse

__all__ = ["MIN_DROP", "MIN_MOVE", "LEVEL", "refit_parameters", "mark_untransferable"]

#: smallest fall of the validation residual power (a share of it) that marks a cause
MIN_DROP = 0.04
#: smallest relative move of one of its parameters that marks it (a right cause whose twin is otherwise short —
#: a residual far above the noise — falls as much by moving its parameters a few per cent: a delay by 3 %)
MIN_MOVE = 0.04
#: significance level of the fall
LEVEL = 0.01
#: least-squares evaluations of one refit
MAX_NFEV = 60


def refit_parameters(twin: Twin, cause: dict[str, Any]) -> list[str]:
    """The cause's continuous parameters that are fields of ``twin.params`` (none for a time-varying effect)."""
    spec = getattr(twin, "EFFECTS", {}).get(cause["effect"])
    if spec is not None and spec.time_varying:
        return []
    info = param_info(type(twin.params))
    names = [k for k, v in cause.get("params", {}).items() if k in info and isinstance(v, float)]
    discrete = set(choice_fields(twin, names)) | set(int_fields(twin, names))
    return [k for k in names if k not in discrete]


def mark_untransferable(
    causes: list[dict[str, Any]],
    twin: Twin,
    est: Record,
    val: Record,
    yhat_val: np.ndarray,
    skip: int = 0,
    say: Callable[[str], Any] | None = None,
) -> None:
    """Refit each catalog cause's parameters on ``val`` alone (``twin``: the extended twin as fitted, ``yhat_val``
    its validation prediction) and mark the causes whose values do not carry over (module docstring), in place;
    ``say`` reports the step. The refit predicts ``val`` as the diagnosis does (:func:`.prediction.simulate_val`:
    from the record's own start state, or continuing ``est``)."""
    work = [(c, names) for c in causes if c["effect"] != "unexplained" and (names := refit_parameters(twin, c))]
    s0 = sse(val.output, yhat_val, skip)
    if not work or not s0 > 0:
        return
    if say is not None:
        say("refitting the named causes on the validation record: do they carry over?")

    def predict(tw: Twin, rec: Record) -> np.ndarray:
        return simulate_val(tw, est, rec)

    for c, names in work:
        try:
            res = calibrate(twin, val, names, skip=skip, simulate=predict, max_nfev=MAX_NFEV)
        except (ConfigError, DataError, ValueError, ArithmeticError):
            continue
        y1 = predict(res.twin, val)
        s1 = sse(val.output, y1, skip)
        drop = 1.0 - s1 / s0
        if not drop >= MIN_DROP:
            continue
        moved = {k: [float(getattr(twin.params, k)), float(res.fitted[k])] for k in names}
        if not max(abs(b - a) / max(abs(a), 1e-300) for a, b in moved.values()) >= MIN_MOVE:
            continue
        p = significance(s0, s1, ft.effective_samples(val.output[skip:] - y1[skip:]), len(names))
        if p >= LEVEL:
            continue
        c["untransferable"] = {"drop": float(drop), "p_value": float(p), "params": moved}
        text = ", ".join(f"{k} {a:.4g} → {b:.4g}" for k, (a, b) in moved.items())
        c["evidence"] = (
            c.get("evidence", "")
            + f"; refitted on the validation record alone its parameters move ({text}) and the validation residual "
            f"power falls by {100 * drop:.0f} % (p = {p:.2g}): the values do not carry over from one record to the "
            "other as one mechanism's would — it may imitate another"
        )
