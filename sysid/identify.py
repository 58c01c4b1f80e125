"""Identify one model as the ``identify`` command does, and hold a nonlinear default against the linear one.

:func:`identify` builds an identifier from ``--set``-style assignments, fits it on the estimation record(s) and
scores it on estimation and validation data (:func:`sysid.evaluation.evaluate.identification_summary`).

A nonlinear model is only worth its parameters when it simulates better than a linear one. When a nonlinear
identifier runs with its defaults (no options given) or with ``auto=true``, the default linear model
(``LINEAR_DEFAULT``, ``arx`` with its orders chosen on a hold-out, :mod:`sysid.linear.order`) is fitted on the same data
and both are scored by their free-run R² on the same hold-out samples (after the larger ``max_lag_`` of the two):

- the validation record when one is given;
- otherwise, with ``auto=true``, the last ``HOLDOUT`` of each estimation record: both are fitted on the rest for
  the comparison, and the one kept is refitted on all the estimation data.

The result is the summary's ``linear_reference`` ({identifier, r2, model_r2, holdout, better}; {identifier,
error} when the comparison could not be made, e.g. a record too short for the hold-out); when the nonlinear model
loses, a warning gives both R². ``auto=true`` then keeps the linear model (summary
``fallback``: {requested, kept, reason}; ``identifier`` is the kept one).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from sysid.config import coerce, parse_assignments
from sysid.data.record import Record
from sysid.errors import ConfigError, DataError, DivergenceWarning
from sysid.evaluation import metrics
from sysid.evaluation.evaluate import identification_summary
from sysid.registry import LINEAR_IDENTIFIERS, get_identifier

__all__ = ["LINEAR_DEFAULT", "LINEAR_IDENTIFIERS", "free_run_r2", "identify", "linear_comparison"]

LINEAR_DEFAULT = "arx"
HOLDOUT = 0.3


def _as_list(data: Record | Sequence[Record]) -> list[Record]:
    return [data] if isinstance(data, Record) else list(data)


def _fit_data(recs: list[Record]) -> Record | list[Record]:
    return recs[0] if len(recs) == 1 else recs


def free_run_r2(models: Sequence[Any], data: Record | Sequence[Record]) -> list[float]:
    """Free-run R² (eq. 2-31) of each model on the same samples: each record after the largest ``max_lag_``."""
    recs = _as_list(data)
    skip = max(int(getattr(m, "max_lag_", 0) or 0) for m in models)
    out = []
    for m in models:
        ys, yhs = [], []
        for r in recs:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DivergenceWarning)
                yhs.append(m.predict(r, None).reshape(r.output.shape)[skip:])
            ys.append(r.output[skip:])
        out.append(float(metrics.score(np.concatenate(ys), np.concatenate(yhs))["r2"]))
    return out


def linear_comparison(
    name: str, model: Any, est: list[Record], val: list[Record] | None, build
) -> tuple[dict[str, Any], Any]:
    """The comparison of the module docstring: ``(linear_reference, linear model fitted on all of est or None)``
    — None when the comparison ran on the internal hold-out and the nonlinear model won (no refit needed).

    ``build()`` makes a fresh unfitted copy of the nonlinear identifier (used for the internal hold-out only)."""
    linear_cls = get_identifier(LINEAR_DEFAULT)
    if val is not None:
        lin = linear_cls().fit(_fit_data(est))
        r_nl, r_lin = free_run_r2([model, lin], val)
        where = "validation record"
    else:
        cuts = [r.split(index=round(len(r) * (1.0 - HOLDOUT))) for r in est]
        fit_part, hold = [a for a, _ in cuts], [b for _, b in cuts]
        nl_part = build().fit(_fit_data(fit_part))
        lin_part = linear_cls().fit(_fit_data(fit_part))
        r_nl, r_lin = free_run_r2([nl_part, lin_part], hold)
        where = f"last {HOLDOUT:.0%} of the estimation data"
        lin = linear_cls().fit(_fit_data(est)) if r_nl < r_lin else None
    better = name if r_nl >= r_lin else LINEAR_DEFAULT
    ref = {
        "identifier": LINEAR_DEFAULT,
        "chosen_orders": getattr(lin, "chosen_orders_", None),
        "holdout": where,
        "r2": r_lin,
        "model_r2": r_nl,
        "better": better,
    }
    return ref, lin


def identify(
    name: str,
    est: Record | Sequence[Record],
    val: Record | Sequence[Record] | None = None,
    assignments: dict[str, str] | Sequence[str] | None = None,
) -> tuple[Any, dict[str, Any]]:
    """Build identifier ``name`` from ``--set``-style assignments, fit on ``est``, score on est/val; for a nonlinear
    identifier run with defaults or ``auto=true``, the comparison with the linear default (module docstring).

    Returns ``(model, summary)`` with the summary in the identify-JSON layout."""
    cls = get_identifier(name)
    if assignments is None:
        assignments = {}
    elif not isinstance(assignments, dict):
        assignments = parse_assignments(assignments)
    assignments = dict(assignments)
    auto = bool(coerce(assignments.pop("auto", False), False, "auto"))
    if auto and name in LINEAR_IDENTIFIERS:
        hint = " (its own orders are chosen with orders=auto)" if name in ("arx", "armax") else ""
        raise ConfigError(
            f"{name}: auto=true holds a nonlinear identifier against the default linear model; {name} is linear{hint}"
        )
    model = cls.from_assignments(assignments)
    t0 = time.perf_counter()
    model.fit(est)
    fit_seconds = time.perf_counter() - t0
    summary = identification_summary(model, est, val, fit_seconds)
    est_l = _as_list(est)
    val_l = None if val is None else _as_list(val)
    if name in LINEAR_IDENTIFIERS or not (auto or not assignments) or (val_l is None and not auto):
        return model, summary
    try:
        ref, lin = linear_comparison(name, model, est_l, val_l, lambda: cls.from_assignments(assignments))
    except (DataError, ConfigError, np.linalg.LinAlgError) as exc:  # e.g. a record too short for the hold-out
        summary["linear_reference"] = {"identifier": LINEAR_DEFAULT, "error": str(exc)}
        return model, summary
    summary["linear_reference"] = ref
    if ref["better"] == name:
        return model, summary
    msg = (
        f"{name} simulates the {ref['holdout']} worse than the default linear model {LINEAR_DEFAULT}: free-run "
        f"R² {ref['model_r2']:.4f} against {ref['r2']:.4f}"
    )
    if not auto:
        summary["warnings"].append(msg + "; identify with --set auto=true keeps the better one")
        return model, summary
    kept = identification_summary(lin, est, val, time.perf_counter() - t0)
    kept["linear_reference"] = ref
    kept["fallback"] = {"requested": name, "kept": LINEAR_DEFAULT, "reason": msg}
    kept["warnings"].insert(0, msg + f"; auto=true: the {LINEAR_DEFAULT} model is kept")
    return lin, kept
