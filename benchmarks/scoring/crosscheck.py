"""SysIdentPy cross-check: its FROLS fitted on the same split as ours, beside each score row.

Skipped with the reason when SysIdentPy is not installed, the dataset has several estimation records, or the run is
quick and the estimation set is larger than :data:`~benchmarks.scoring.settings.SYSIDENTPY_QUICK_MAX_EST`.
"""

from __future__ import annotations

import hashlib
import json
import time
import warnings
from typing import Any

import numpy as np

from benchmarks.scoring.settings import METRICS, SYSIDENTPY_QUICK_MAX_EST, sysidentpy_settings
from sysid.data.jsonio import clean_json
from sysid.evaluation.metrics import score as metric_score


def sysidentpy_frols(ds, quick: bool = False, use_cache: bool = True) -> list[dict[str, Any]]:
    """SysIdentPy's FROLS (polynomial NARX, least squares, AIC order selection) on the same split as ours.

    Returns one row per test with free-run and one-step metrics, or rows with ``status: skipped`` and the
    reason. Results are cached (SysIdentPy is slow) under the dataset cache, keyed by data and settings.
    """
    try:
        import sysidentpy
        from sysidentpy.basis_function import Polynomial
        from sysidentpy.model_structure_selection import FROLS
        from sysidentpy.parameter_estimation import LeastSquares
    except ImportError as exc:
        return [
            {"dataset": ds.name, "test": t, "status": "skipped", "reason": f"SysIdentPy not installed ({exc})"}
            for t in ds.tests
        ]
    cfg = sysidentpy_settings(ds.name)
    est = ds.est_records
    if len(est) != 1:
        return [
            {
                "dataset": ds.name,
                "test": t,
                "status": "skipped",
                "reason": "SysIdentPy fits one record; this dataset has several",
            }
            for t in ds.tests
        ]
    est = est[0]
    if quick and len(est) > SYSIDENTPY_QUICK_MAX_EST:
        return [
            {
                "dataset": ds.name,
                "test": t,
                "status": "skipped",
                "reason": f"quick run: estimation set of {len(est)} samples > {SYSIDENTPY_QUICK_MAX_EST}",
            }
            for t in ds.tests
        ]
    h = hashlib.sha256()
    for rec in [est, *ds.tests.values()]:
        h.update(np.ascontiguousarray(rec.u).tobytes())
        h.update(np.ascontiguousarray(rec.y).tobytes())
    cache_key = {"cfg": cfg, "version": sysidentpy.__version__, "init": ds.init_samples}
    if ds.test_init:  # per-test windows (kept out of the key otherwise, so earlier cached fits stay valid)
        cache_key["test_init"] = ds.test_init
    h.update(json.dumps(cache_key, sort_keys=True).encode())
    from benchmarks.datasets.twin import cache_dir

    cache = cache_dir() / "sysidentpy" / f"{ds.name}-{h.hexdigest()[:16]}.json"
    if use_cache and cache.exists():
        return json.loads(cache.read_text())
    model = FROLS(
        order_selection=True,
        n_info_values=cfg["n_info_values"],
        ylag=cfg["ylag"],
        xlag=cfg["xlag"],
        info_criteria="aic",
        estimator=LeastSquares(),
        basis_function=Polynomial(degree=cfg["degree"]),
    )
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(X=est.u.reshape(-1, 1), y=est.y.reshape(-1, 1))
    fit_s = time.perf_counter() - t0
    max_lag = int(model.max_lag)
    rows = []
    for t, rec in ds.tests.items():
        x, y = rec.u.reshape(-1, 1), rec.y.reshape(-1, 1)
        skip = max(ds.init_for(t), max_lag)
        row = {
            "dataset": ds.name,
            "test": t,
            "status": "ok",
            "settings": cfg,
            "fit_seconds": fit_s,
            "n_parameters": int(len(model.final_model)),
            "skip": skip,
            "sysidentpy_version": sysidentpy.__version__,
        }
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            for key, steps in (("free_run", None), ("one_step", 1)):
                yhat = np.asarray(
                    model.predict(X=x, y=y[:max_lag], steps_ahead=None)
                    if steps is None
                    else model.predict(X=x, y=y, steps_ahead=1),
                    dtype=float,
                ).reshape(-1)
                # SysIdentPy returns the series aligned with the input; guard against off-by-one lengths
                yhat = (
                    yhat[: len(rec)]
                    if yhat.size >= len(rec)
                    else np.concatenate([yhat, np.full(len(rec) - yhat.size, np.nan)])
                )
                s = metric_score(rec.y, yhat, skip=skip)
                row[key] = {m: s[m] for m in METRICS}
        rows.append(row)
    if use_cache:
        cache.parent.mkdir(parents=True, exist_ok=True)
        from sysid.data.safeio import atomic_write_text

        atomic_write_text(cache, json.dumps(clean_json(rows)))
    return rows
