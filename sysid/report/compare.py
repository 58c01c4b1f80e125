"""Using identified models on new data: predictions with their fit, and the MATLAB-``compare``-like table.

- :func:`parse_horizon` — ``"1"``, ``"K"`` or ``"inf"`` (free run) from the command line;
- :func:`check_rate` — a model applies only to data at the rate it was identified at;
- :func:`predict_scores` — prediction of one model on one record plus, when ``y`` is there, the fit metrics of
  :mod:`sysid.evaluation.metrics`: NRMSE fit % (MATLAB's ``fit = 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖)``), R² (eq. 2-31), RMSE;
- :func:`compare` — several models on one record, scored on the same samples (after the largest ``max_lag_``
  of all of them, the initial conditions copied from the measurement);
- :func:`fir_reference` — the least-squares FIR (``identify fir`` with its defaults) fitted on estimation data, the
  baseline ``compare --fir-est`` shows beside the user's models;
- :func:`compare_report` — the figures: measured vs predicted (whole record and a zoom) and the residual
  correlation tests (eq. 2-32) of each model's one-step residuals (what MATLAB's ``resid`` tests).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sysid.data.record import Record
from sysid.errors import ConfigError, DataError, DivergenceWarning
from sysid.evaluation import metrics

__all__ = [
    "parse_horizon",
    "horizon_label",
    "check_rate",
    "predict_scores",
    "compare",
    "compare_report",
    "fir_reference",
]

#: relative difference between the data's and the model's sampling rate still accepted
RATE_TOLERANCE = 1e-6
FREE_RUN_WORDS = ("inf", "none", "free", "free-run", "sim")


def parse_horizon(text: str | int | None) -> int | None:
    """``1`` (one step), ``K`` (true K-step-ahead at every sample) or ``inf`` (free-run simulation: None)."""
    if text is None:
        return None
    if isinstance(text, int) and not isinstance(text, bool):
        value = text
    else:
        s = str(text).strip().lower()
        if s in FREE_RUN_WORDS:
            return None
        try:
            value = int(s)
        except ValueError:
            raise ConfigError(f"--horizon must be 1, a positive integer K or inf (free run), got {text!r}") from None
    if value < 1:
        raise ConfigError(f"--horizon must be 1, a positive integer K or inf (free run), got {text!r}")
    return value


def horizon_label(h: int | None) -> str:
    return "free run" if h is None else ("one-step" if h == 1 else f"{h}-step")


def check_rate(model, record: Record) -> None:
    """Refuse data at another sampling rate than the model's estimation data (when the file says which)."""
    fs_model = getattr(model, "fs_", None)
    if fs_model and not math.isclose(record.fs, fs_model, rel_tol=RATE_TOLERANCE):
        raise DataError(
            f"{record.source}: sampled at {record.fs:.10g} Hz, but the model was identified at "
            f"{fs_model:.10g} Hz; resample the data first (piezotwin preprocess)"
        )


def _predict(model, record: Record, horizon: int | None) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DivergenceWarning)
        return np.asarray(model.predict(record, horizon), dtype=float)


def predict_scores(
    model, record: Record, horizon: int | None, skip: int | None = None
) -> tuple[np.ndarray, dict[str, Any]]:
    """(prediction, summary). Summary: ``horizon, initial_conditions, skip, diverged_at`` and ``metrics``
    (``fit_percent, r2, rmse, nrmse, mse``; ``None`` when the record has no measured ``y``)."""
    if record.y is None and horizon is not None:
        raise ConfigError(f"{record.source}: has no output y, so only a free run (--horizon inf) is possible")
    check_rate(model, record)
    yh = _predict(model, record, horizon)
    skip = int(getattr(model, "max_lag_", 0) or 0) if skip is None else int(skip)
    div = getattr(model, "diverged_at_", None)
    out: dict[str, Any] = {
        "horizon": "inf" if horizon is None else int(horizon),
        "initial_conditions": "measured" if record.y is not None else "zero",
        "skip": skip,
        "diverged_at": None if div is None else int(div),
        "metrics": None,
    }
    if record.y is not None:
        out["metrics"] = metrics.score(record.y, yh.reshape(record.y.shape), skip=skip)
    return yh, out


def compare(
    models: Sequence[Any], record: Record, horizon: int | None = None, names: Sequence[str] | None = None
) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
    """Predict ``record`` with every model and score all on the same samples (after the largest max_lag_)."""
    record.require_output()
    names = list(names) if names is not None else [m.name for m in models]
    skip = max(int(getattr(m, "max_lag_", 0) or 0) for m in models)
    preds, rows = [], []
    for name, m in zip(names, models):
        yh, s = predict_scores(m, record, horizon, skip=skip)
        s = {"model": name, "identifier": m.name, **s}
        preds.append(yh)
        rows.append(s)
    return preds, rows


def fir_reference(est: Record | Sequence[Record]):
    """The least-squares FIR of the ``fir`` identifier with its defaults (taps chosen on a hold-out of ``est``):
    the baseline every practitioner fits first, to be compared beside other models (:mod:`sysid.linear.fir`)."""
    from sysid.registry import get_identifier

    return get_identifier("fir")().fit(est)


def compare_report(
    models: Sequence[Any],
    names: Sequence[str],
    record: Record,
    preds: Sequence[np.ndarray],
    rows: Sequence[dict[str, Any]],
    out_dir: str | Path,
    max_lag: int = 20,
) -> dict[str, Any]:
    """Write ``compare.png`` (measured vs predicted, whole record and zoom) and ``residual_tests_<n>.png``
    (correlation tests of each model's one-step residuals); return the paths and the test results."""
    from sysid.evaluation.residuals import correlation_tests
    from sysid.report.plots import plot_compare, plot_correlation_tests

    out = Path(out_dir)
    skip = rows[0]["skip"] if rows else 0
    y = record.output if record.output.ndim == 1 else record.output[:, 0]
    u = record.u if record.u.ndim == 1 else record.u[:, 0]
    labels = []
    for row in rows:
        fit = row["metrics"]["fit_percent"]
        labels.append(f"{row['model']}: fit {fit:.2f} %" if np.isfinite(fit) else f"{row['model']}: diverged")
    curves = [(p if p.ndim == 1 else p[:, 0]) for p in preds]
    files: dict[str, Any] = {
        "compare": str(
            plot_compare(
                record.t,
                y,
                curves,
                labels,
                out / "compare.png",
                skip=skip,
                title=f"measured vs {horizon_label(_h(rows))} prediction",
                unit=record.units.get("y", ""),
            )
        )
    }
    tests = {}
    for k, (name, m) in enumerate(zip(names, models)):
        y1 = _predict(m, record, 1)
        y1 = y1 if y1.ndim == 1 else y1[:, 0]
        L = int(getattr(m, "max_lag_", 0) or 0)
        e = (y - y1)[L:]
        if not np.isfinite(e).all() or e.size < 8:
            continue
        res = correlation_tests(e, u[L:], max_lag=min(max_lag, e.size - 2))
        tag = f"{k + 1}"
        files[f"residual_tests_{tag}"] = str(
            plot_correlation_tests(res, out / f"residual_tests_{tag}.png", title=f"{name}: one-step residual tests")
        )
        tests[name] = {"passed": res["passed"], "failed": [t["name"] for t in res["tests"] if not t["passed"]]}
    return {"files": files, "residual_tests": tests}


def _h(rows: Sequence[dict[str, Any]]) -> int | None:
    h = rows[0]["horizon"] if rows else None
    return None if h == "inf" else h
