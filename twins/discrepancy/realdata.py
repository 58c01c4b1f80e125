"""The steps that make the diagnosis hold on measured records, around its loop (:func:`twins.discrepancy.diagnose`):
the split and ranges before anything is fitted (:mod:`.splitting`, :mod:`.ranges`), the core's calibration (the
twin's own, or output error where it refuses the record), the widened refit of a baseline that ends at a bound, and
the verdict against the noise measured from the data (:mod:`.unexplained`). The default-effect re-test is
:mod:`.defaults`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError
from twins.base import Twin
from twins.calibration import CalibrationResult
from twins.calibration import calibrate as ls_calibrate

from . import ranges as rg
from . import splitting
from . import unexplained as unx

__all__ = ["prepare", "calibrate_core", "refit_at_bounds", "final_verdict"]


def prepare(
    twin: Twin, data: Record, val: Record | None, split: float, follow_ranges: bool
) -> tuple[Twin, Record, Record, dict[str, Any], list[str]]:
    """Split (validation with excitation, or a ``val`` that has it) and the twin's ranges from the records."""
    data.require_output()
    if val is None:
        data, val, split_info = splitting.choose_split(data, split)
    else:
        val.require_output()
        split_info = splitting.check_validation(data, val)
    notes: list[str] = []
    if follow_ranges and isinstance(twin, Twin) and data.u.ndim == 1 and val.u.ndim == 1:
        twin, notes = rg.follow_record(twin, data, val)
    return twin, data, val, split_info, notes


def calibrate_core(
    twin: Twin, est: Record, val: Record, names: list[str], own: bool, simulate: Callable
) -> CalibrationResult[Twin]:
    """The core ``names`` of ``twin`` fitted to ``est``: by the twin's own calibration where ``own`` (it knows its
    physics: the acoustic stack from the H1 frequency response), else — and where that one refuses the record (one
    tone burst excites fewer frequencies than it needs; diagnosis benchmark seed 666) — by the generic output-error
    fit (:func:`twins.calibration.calibrate`), which the diagnosis then keeps only if it beats the noise."""
    if own:
        try:
            return twin.calibrate(est, val=val, names=names)
        except DataError:
            pass
    return ls_calibrate(twin, est, names, val=val, simulate=simulate)


def refit_at_bounds(
    fitted: Twin,
    names: list[str],
    data: Record,
    sse: Callable[[Twin], float],
    simulate: Callable,
    say: Callable[[str], None],
) -> tuple[Twin, dict[str, Any] | None]:
    """When a fitted parameter of ``names`` ends within 1 % of its bound, refit once with the bound widened
    (:func:`.ranges.widened`); returns the better twin and, when the refit was kept, its calibration info."""
    hits = rg.at_bounds(fitted, names)
    if not hits:
        return fitted, None
    wide, rows = rg.widened(fitted, hits)
    if not rows:
        return fitted, None
    say("refitting with widened bounds: " + ", ".join(r["param"] for r in rows))
    try:
        res = ls_calibrate(wide, data, names, simulate=simulate)
    except (ConfigError, DataError, ValueError, np.linalg.LinAlgError):
        return fitted, None
    if sse(res.twin) < sse(fitted):
        return res.twin, {"fitted": res.fitted, "stderr": res.stderr, "widened": rows}
    return fitted, None


def final_verdict(
    val: Record,
    yhat_val: np.ndarray,
    causes: list[dict[str, Any]],
    twin: Twin,
    calib_info: dict[str, Any],
    skip: int,
    noise: dict[str, Any],
) -> tuple[str, dict[str, Any], list[dict[str, Any]]]:
    """(verdict, residual against noise, parameters at a bound): ``unexplained`` when the validation residual
    after the extension is far above ``noise`` (:func:`.unexplained.noise_level` of both records, measured from
    the data), else ``discrepancy`` with causes or ``none``."""
    beyond = unx.judge(val.u, val.output, yhat_val, val.fs, skip, noise=noise)
    verdict = "unexplained" if beyond["outside"] else ("discrepancy" if causes else "none")
    names = set(calib_info.get("fitted", {})) | {k for c in causes for k in c.get("params", {})}
    at_bound = rg.at_bounds(twin, sorted(names)) + [
        {**r, "value": float(getattr(twin.params, r["param"]))} for r in calib_info.get("widened", [])
    ]
    return verdict, beyond, at_bound
