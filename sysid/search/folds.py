"""How one run of a sweep is fitted and scored: on a validation record (:func:`fit_scored`), or by blocked k-fold
cross-validation on the estimation record (:func:`evaluate_folds`, ``search --folds K``).

Where no separate validation record exists, or one split of the record would rank structures by a single stretch
of it, each configuration is fitted K times: fold i holds the i-th contiguous block of the estimation record out
and fits on the rest (:meth:`sysid.data.record.Record.blocked_folds`), then scores the model one step ahead and in
free run on the block it did not see (Bergmeir & Benítez, "On the use of cross-validation for time series
predictor evaluation", Inf. Sci. 191, 2012). A run's scores are the means over its folds, so the sweep's tables,
objective and exports read them as they read a validation record's; the folds' own scores travel with the run.
A fold whose free run diverges makes the run's mean free-run R² non-finite: the run counts as diverged.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import DivergenceWarning

__all__ = ["fit_scored", "evaluate_folds", "mean_scores"]


def fit_scored(model: Any, est: Record | Sequence[Record], val: Record | Sequence[Record]) -> dict[str, Any]:
    """Fit ``model`` on ``est`` (a diverging free run is scored, not warned about) and score it on ``est`` and
    ``val``: its parameter count, fit time [s] and the identify-JSON scores of both (one run, or one fold of one)."""
    from sysid.evaluation.evaluate import evaluate

    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DivergenceWarning)
        model.fit(est)
    fit_s = time.perf_counter() - t0
    return {
        "n_parameters": model.n_parameters_,
        "fit_seconds": fit_s,
        "estimation": evaluate(model, est),
        "validation": evaluate(model, val),
    }


def mean_scores(scores: list[dict[str, Any]]) -> dict[str, Any]:
    """The mean of :func:`sysid.evaluation.evaluate.evaluate` dicts, metric by metric (``diverged_at`` becomes
    ``diverged_folds``, the number of folds whose free run diverged)."""
    out: dict[str, Any] = {}
    for mode in scores[0]:
        entry: dict[str, Any] = {}
        for metric in scores[0][mode]:
            if metric == "diverged_at":
                continue
            entry[metric] = float(np.mean([s[mode][metric] for s in scores]))
        diverged = sum("diverged_at" in s[mode] for s in scores)
        if diverged:
            entry["diverged_folds"] = diverged
        out[mode] = entry
    return out


def evaluate_folds(make_model: Callable[[], Any], est: Record, k: int) -> dict[str, Any]:
    """Fit ``make_model()`` on each of the ``k`` blocked folds of ``est`` and score it on what it was fitted on
    (``estimation``) and on the block it was not (``validation``); means over the folds, the parameter count of
    the folds' models (their mean, rounded, where a structure selection differs between folds), the summed fit
    time, and each fold's scores under ``folds``."""
    per: list[dict[str, Any]] = []
    start = 0
    for i, (parts, block) in enumerate(est.blocked_folds(k)):
        scored = fit_scored(make_model(), parts[0] if len(parts) == 1 else parts, block)
        per.append({"fold": i, "held_out": [start, start + len(block)], **scored})  # [start, stop) of the block
        start += len(block)
    return {
        "n_parameters": int(round(float(np.mean([f["n_parameters"] for f in per])))),
        "fit_seconds": float(sum(f["fit_seconds"] for f in per)),
        "estimation": mean_scores([f["estimation"] for f in per]),
        "validation": mean_scores([f["validation"] for f in per]),
        "folds": per,
    }
