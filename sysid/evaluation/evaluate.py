"""Evaluation of any fitted identifier on records: one-step and free-run R² / NRMSE (dissertation §2.7–2.8).

Shared by the ``identify`` command, the benchmarks and the neural identifiers: it needs only the
:class:`~sysid.base.Identifier` interface (``predict(record, horizon)``, ``max_lag_``, ``describe()``).
Metrics skip the first ``max_lag_`` samples of each record (copied initial conditions). A list of Records is
scored on their concatenated samples. A diverged free run scores ``nan`` (JSON ``null``) and reports
``diverged_at``.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import DivergenceWarning
from sysid.evaluation import metrics

__all__ = ["evaluate", "identification_summary"]

MODES = {"one_step": 1, "free_run": None}


def _records(data: Record | Sequence[Record]) -> list[Record]:
    return [data] if isinstance(data, Record) else list(data)


def evaluate(
    model, data: Record | Sequence[Record], horizons: dict[str, int | None] | None = None, all_metrics: bool = False
) -> dict[str, Any]:
    """Scores per prediction mode: ``{"one_step": {"r2", "nrmse"}, "free_run": {...}}``.

    ``horizons`` maps a key to a horizon (default one_step → 1, free_run → None); ``all_metrics`` adds mse,
    rmse and fit_percent. A free run that diverged adds ``diverged_at`` (index in its record).
    """
    horizons = MODES if horizons is None else horizons
    recs = _records(data)
    skip = int(getattr(model, "max_lag_", 0) or 0)
    out: dict[str, Any] = {}
    for key, h in horizons.items():
        ys, yhs = [], []
        diverged = None
        for rec in recs:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", DivergenceWarning)
                yh = np.asarray(model.predict(rec, horizon=h), dtype=float)
            if getattr(model, "diverged_at_", None) is not None and diverged is None:
                diverged = int(model.diverged_at_)
            ys.append(np.asarray(rec.y, dtype=float)[skip:])
            yhs.append(yh.reshape(np.shape(rec.output))[skip:])
        y = np.concatenate(ys)
        yh = np.concatenate(yhs)
        s = metrics.score(y, yh)
        entry = s if all_metrics else {"r2": s["r2"], "nrmse": s["nrmse"]}
        if diverged is not None:
            entry["diverged_at"] = diverged
        out[key] = entry
    return out


def identification_summary(
    model,
    est: Record | Sequence[Record],
    val: Record | Sequence[Record] | None = None,
    fit_seconds: float | None = None,
) -> dict[str, Any]:
    """The ``identify`` JSON (interfaces.md): identifier, params, n_parameters, fit_seconds, terms, estimation,
    validation (``None`` without validation data); linear models add ``parameters`` ([{name, value, std}]),
    ``poles`` and ``chosen_orders`` (with ``order_selection`` and ``order_search`` when chosen automatically), the
    FIR its ``taps``; ``warnings`` lists practitioner warnings (:mod:`sysid.evaluation.advice`)."""
    d = model.describe()
    out = {
        "identifier": d.get("identifier", getattr(model, "name", type(model).__name__)),
        "params": d.get("params", {}),
        "n_parameters": d.get("n_parameters", getattr(model, "n_parameters_", None)),
        "fit_seconds": fit_seconds,
        "terms": list(d.get("terms", []) or []),
        "estimation": evaluate(model, est),
        "validation": evaluate(model, val) if val is not None else None,
    }
    # linear models: parameters with std, poles, automatically chosen orders
    for key in ("parameters", "poles", "chosen_orders", "nx", "order_selection", "order_search", "taps"):
        if d.get(key) is not None:
            out[key] = d[key]
    if "order_search" not in out and getattr(model, "order_search_", None) and out.get("chosen_orders"):
        out["order_search"] = model.order_search_  # oe / bj keep it beside their order table
    from sysid.evaluation.advice import practitioner_warnings

    out["warnings"] = practitioner_warnings(model, est, val, out)
    return out
