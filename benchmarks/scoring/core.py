"""Scoring core: identifiers × datasets → test accuracy, fit time, parameter count.

For every identifier (registry id, :mod:`sysid.registry`) and dataset (:mod:`benchmarks.datasets`) the
identifier is fitted on the estimation data with the settings of :mod:`benchmarks.scoring.settings` and predicts
every test set one step ahead and in free run (``predict(record, horizon=1)`` / ``horizon=None``). Metrics
(:mod:`sysid.evaluation.metrics`)
skip the first ``max(dataset.init_for(test), model.max_lag_)`` samples of each test — the
official initialisation window, or the model's own initial conditions if it needs more. Beside each row: the
published reference numbers of that test (:mod:`benchmarks.datasets.references`) and SysIdentPy's FROLS fitted
on the same split (:mod:`benchmarks.scoring.crosscheck`).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeGuard

import numpy as np

from benchmarks.scoring.settings import (
    FULL_ONLY_DATASETS,
    METRICS,
    NORMALISE,
    QUICK_DATASETS,
    QUICK_MAX_SAMPLES,
    QUICK_ONLY_DATASETS,
    QUICK_SEEDS,
    QUICK_SKIP_IDENTIFIERS,
    QUICK_SKIP_TESTS,
    seeds_for,
    settings_for,
)
from sysid.data.record import NormalisedModel, Record
from sysid.errors import ConfigError, InputError


class _Scored:
    """Proxy of a fitted model for :func:`sysid.evaluation.evaluate.evaluate`: reports ``max_lag_`` = the scoring skip
    (max of the dataset's initialisation window and the model's own lags) and keeps the predictions."""

    def __init__(self, model, skip: int):
        self.model, self.max_lag_ = model, skip
        self.outputs: dict[Any, np.ndarray] = {}

    def predict(self, record: Record, horizon: int | None = 1) -> np.ndarray:
        y = self.model.predict(record, horizon=horizon)
        self.outputs[horizon] = np.asarray(y, dtype=float)
        return y

    @property
    def diverged_at_(self):
        return getattr(self.model, "diverged_at_", None)


def evaluate(model, record: Record, init_samples: int = 0) -> dict[str, Any]:
    """One-step and free-run metrics of a fitted ``model`` on ``record``, scored from sample
    ``max(init_samples, model.max_lag_)`` on — the poly team's :func:`sysid.evaluation.evaluate.evaluate` on a proxy."""
    from sysid.evaluation.evaluate import evaluate as sysid_evaluate

    skip = max(int(init_samples), int(getattr(model, "max_lag_", 0) or 0))
    proxy = _Scored(model, skip)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ev = sysid_evaluate(proxy, record, all_metrics=True)
    out: dict[str, Any] = {"skip": skip, "n_scored": len(record) - skip}
    for key in ("one_step", "free_run"):
        out[key] = {m: ev[key][m] for m in METRICS}
    yfr = proxy.outputs.get(None)
    out["diverged"] = bool(yfr is None or not np.isfinite(yfr[skip:]).all())
    if "diverged_at" in ev["free_run"]:
        out["diverged_at"] = ev["free_run"]["diverged_at"]
    out["warnings"] = sorted({str(w.message).splitlines()[0][:200] for w in caught})
    out["_yhat_free_run"] = yfr
    return out


@dataclass
class ScoreRun:
    """Rows of one scoring run (one per identifier × dataset × test) plus what was skipped and why."""

    quick: bool
    rows: list[dict[str, Any]] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)
    sysidentpy: list[dict[str, Any]] = field(default_factory=list)
    predictions: dict[tuple[str, str, str], np.ndarray] = field(default_factory=dict, repr=False)
    datasets: dict[str, Any] = field(default_factory=dict, repr=False)
    seconds: float = 0.0
    selection: dict[str, list[str]] = field(default_factory=dict)  # identifiers and datasets asked for
    environment: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "piezotwin-score/1",
            "mode": "quick" if self.quick else "full",
            "rows": self.rows,
            "sysidentpy": self.sysidentpy,
            "skipped": self.skipped,
            "seconds": self.seconds,
            "selection": self.selection,
            "environment": self.environment,
        }


#: keys of a score run that measure time: two runs of the same command differ in them only
TIMING_KEYS = ("seconds", "fit_seconds", "fit_seconds_mean")


def strip_timing(obj: Any) -> Any:
    """A score run (or any part of its JSON) without its :data:`TIMING_KEYS`: what two runs of the same
    command share exactly, wherever they ran."""
    if isinstance(obj, dict):
        return {k: strip_timing(v) for k, v in obj.items() if k not in TIMING_KEYS}
    if isinstance(obj, list):
        return [strip_timing(v) for v in obj]
    return obj


def blas_kernels() -> str:
    """The kernel set each loaded BLAS runs ("openblas:SkylakeX"), as threadpoolctl reads it from the library.

    OpenBLAS picks its kernels from the CPU unless ``OPENBLAS_CORETYPE`` names a set; the floors are measured
    over several sets (docs/regression-check.md), so a run records which one it had."""
    from threadpoolctl import threadpool_info

    sets = sorted(
        {
            f"{i.get('internal_api', '?')}:{i.get('architecture') or '?'}"
            for i in threadpool_info()
            if i.get("user_api") == "blas"
        }
    )
    return ",".join(sets)


def environment() -> dict[str, Any]:
    """What a floor measured in this process depends on: CPU, torch's and OpenBLAS's kernel sets, thread
    settings, versions."""
    import os
    import platform

    import scipy

    env: dict[str, Any] = {"machine": platform.machine(), "cpu": platform.processor() or ""}
    try:
        with open("/proc/cpuinfo") as fh:
            env["cpu"] = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")), env["cpu"])
    except OSError:
        pass
    env["ATEN_CPU_CAPABILITY"] = os.environ.get("ATEN_CPU_CAPABILITY", "")
    env["OPENBLAS_NUM_THREADS"] = os.environ.get("OPENBLAS_NUM_THREADS", "")
    env["OPENBLAS_CORETYPE"] = os.environ.get("OPENBLAS_CORETYPE", "")
    env["blas_kernels"] = blas_kernels()
    versions = {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__}
    try:
        import torch

        env["torch_cpu_capability"] = torch.backends.cpu.get_cpu_capability()
        versions["torch"] = torch.__version__
    except ImportError:  # pragma: no cover - torch is a dependency
        pass
    env["versions"] = versions
    return env


def _quick_cut(rec: Record, n: int | None) -> Record:
    return rec if n is None or len(rec) <= n else rec[:n]


def prepare_dataset(ds, quick: bool):
    """Apply the quick-mode sample budget (QUICK_MAX_SAMPLES) and test selection (QUICK_SKIP_TESTS) to a loaded
    Dataset, in place; returns it."""
    if not quick:
        return ds
    skip = QUICK_SKIP_TESTS.get(ds.name, {}).get("tests", [])
    if skip:
        ds.tests = {k: v for k, v in ds.tests.items() if k not in skip}
        ds.meta["quick_skipped_tests"] = list(skip)
    if ds.name not in QUICK_MAX_SAMPLES:
        return ds
    lim = QUICK_MAX_SAMPLES[ds.name]
    if isinstance(ds.est, Record):
        ds.est = _quick_cut(ds.est, lim.get("est"))
    ds.tests = {k: _quick_cut(v, lim.get("test")) for k, v in ds.tests.items()}
    ds.meta["quick_max_samples"] = lim
    return ds


def _median_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """The run of median free-run RMSE (a diverged or non-finite run counts as +inf; the lower median for an even
    count), so the scored row is one real model with consistent metrics."""

    def key(ev: dict[str, Any]) -> float:
        rmse = (ev.get("free_run") or {}).get("rmse")
        return rmse if _finite(rmse) and not ev.get("diverged") else math.inf

    order = sorted(range(len(runs)), key=lambda k: key(runs[k]))
    return runs[order[(len(runs) - 1) // 2]]


def score_pair(
    identifier: str,
    ds,
    quick: bool = False,
    factory: Callable[[str], Any] | None = None,
    params: dict[str, Any] | None = None,
    seeds: Sequence[int] | None = None,
) -> tuple[list[dict[str, Any]], dict[str, np.ndarray]]:
    """Fit ``identifier`` on ``ds.est`` and score every test of ``ds``; returns (rows, free-run predictions).

    A seeded identifier is fitted once per seed of ``seeds`` (default: :data:`QUICK_SEEDS` in quick mode, the
    identifier's own seed in a full run) and each test is scored by the run of median free-run RMSE
    (:func:`_median_run`); the row lists every seed's RMSE and their mean and SD. BLAS runs
    single-threaded (wherever the pair runs: in-process or in a worker), so no number depends on the core count."""
    from sysid._blas import blas_threads

    with blas_threads(1):
        return _score_pair(identifier, ds, quick, factory, params, seeds)


def _score_pair(
    identifier, ds, quick, factory, params, seeds=None
) -> tuple[list[dict[str, Any]], dict[str, np.ndarray]]:
    outcomes = [_fit_seed(identifier, ds, quick, factory, params, seeds, k) for k in range(_max_seeds(quick, seeds))]
    return _assemble(identifier, ds, quick, params, outcomes, seeds)


def _plan(identifier, ds, quick, factory, params, seeds) -> tuple[Any, dict[str, Any], bool, tuple[int | None, ...]]:
    """The identifier class, its options (without the normalise flag), the flag and the seeds of one pair."""
    from sysid.registry import get_identifier

    cls = (factory or get_identifier)(identifier)
    params, normalise = _options(identifier, ds, quick, params)
    return cls, params, normalise, seeds_for(cls, params, quick, seeds)


def _options(identifier, ds, quick, params) -> tuple[dict[str, Any], bool]:
    """The pair's identifier options without the normalise flag, and the flag."""
    params = dict(settings_for(identifier, ds.name, quick) if params is None else params)
    return params, bool(params.pop(NORMALISE, False))


def _max_seeds(quick: bool, seeds: Sequence[int] | None) -> int:
    """How many seed tasks a pair may need: the seeds asked for (quick or full mode), else the quick seeds in
    quick mode, else one (a full run trains the identifier's default seed)."""
    if seeds is not None:
        return len(seeds)
    return len(QUICK_SEEDS) if quick else 1


def _fit_seed(identifier, ds, quick, factory, params, seeds, k: int) -> dict[str, dict[str, Any]] | None:
    """Fit the ``k``-th training seed of one pair and evaluate every test: {test: evaluation}; None when the
    pair has fewer than ``k + 1`` seeds (an identifier without a seed is fitted once)."""
    cls, params, normalise, pair_seeds = _plan(identifier, ds, quick, factory, params, seeds)
    if k >= len(pair_seeds):
        return None
    seed = pair_seeds[k]
    model = cls(**params) if seed is None else cls(**params, seed=seed)
    if normalise:
        model = NormalisedModel(model)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(ds.est)
    fit_s = time.perf_counter() - t0
    out = {}
    for test, rec in ds.tests.items():
        ev = evaluate(model, rec, ds.init_for(test))
        ev.update(seed=seed, fit_seconds=fit_s, n_parameters=getattr(model, "n_parameters_", None))
        out[test] = ev
    return out


def _assemble(
    identifier, ds, quick, params, outcomes, seeds=None
) -> tuple[list[dict[str, Any]], dict[str, np.ndarray]]:
    """Rows and free-run predictions of one pair from its seeds' evaluations (in seed order; None for a seed
    the pair does not have). Needs no identifier class, so the parent of Dask tasks does not import one.

    A seeded row lists every seed's free-run and one-step RMSE and the mean and sample SD of the free-run RMSE
    over the seeds that stayed finite; when ``seeds`` were asked for and the pair was fitted once (no training
    seed, or one fixed by the settings), the row says ``"seeds": "deterministic"`` with that one value as mean."""
    params, normalise = _options(identifier, ds, quick, params)
    outcomes = [o for o in outcomes if o is not None]
    runs = {test: [o[test] for o in outcomes] for test in ds.tests}
    pair_seeds = [o[next(iter(ds.tests))]["seed"] for o in outcomes] if ds.tests else []
    if normalise:
        params[NORMALISE] = True
    rows, preds = [], {}
    for test, rec in ds.tests.items():
        ev = dict(_median_run(runs[test]))
        preds[test] = ev.pop("_yhat_free_run")
        seed, fit_s, n_par = ev.pop("seed"), ev.pop("fit_seconds"), ev.pop("n_parameters")
        row = {
            "identifier": identifier,
            "dataset": ds.name,
            "test": test,
            "status": "diverged" if ev["diverged"] else "ok",
            "params": params,
            "n_parameters": n_par,
            "fit_seconds": fit_s,
            "n_est": sum(len(r) for r in ds.est_records),
            "n_test": len(rec),
            "units": ds.units.get("y", ""),
            **ev,
            "references": ds.references.get(test, {}),
        }
        if seed is not None:
            row.update(seed=seed, seeds=list(pair_seeds), **_seed_columns(runs[test]))
        elif seeds is not None:
            rmse = ev["free_run"]["rmse"]
            row.update(
                seeds="deterministic",
                free_run_rmse_mean=rmse if _finite(rmse) else None,
                free_run_rmse_sd=0.0 if _finite(rmse) else None,
                fit_seconds_mean=fit_s,
            )
        rows.append(row)
    return rows, preds


def _seed_columns(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per-seed free-run and one-step RMSE of one test (None where not finite), the mean and sample SD of the
    finite free-run values (SD 0 for one value; None when none is finite) and the mean fit time."""

    def finite(key: str) -> list[float | None]:
        vals = [(r.get(key) or {}).get("rmse") for r in runs]
        return [x if _finite(x) else None for x in vals]

    free = finite("free_run")
    ok = np.array([x for x in free if x is not None], dtype=float)
    return {
        "free_run_rmse_by_seed": free,
        "one_step_rmse_by_seed": finite("one_step"),
        "free_run_rmse_mean": float(ok.mean()) if ok.size else None,
        "free_run_rmse_sd": (float(ok.std(ddof=1)) if ok.size > 1 else 0.0) if ok.size else None,
        "fit_seconds_mean": float(np.mean([r["fit_seconds"] for r in runs])),
    }


def _guarded(identifier: str, ds, body: Callable[[], Any]) -> tuple[str, Any]:
    """``("ok", body())``; a ConfigError is ``("skip", entry)`` and any other exception of the identifier
    ``("error", rows)``: a failing pair is a result, not a crashed run."""
    try:
        return "ok", body()
    except ConfigError as exc:
        return "skip", {"identifier": identifier, "dataset": ds.name, "reason": str(exc)}
    except Exception as exc:
        return "error", [
            {
                "identifier": identifier,
                "dataset": ds.name,
                "test": t,
                "status": "error",
                "message": f"{type(exc).__name__}: {exc}"[:300],
                "references": ds.references.get(t, {}),
            }
            for t in ds.tests
        ]


def _outcome(status: str, value: Any) -> tuple[list[dict[str, Any]], dict[str, np.ndarray], dict[str, str] | None]:
    if status == "skip":
        return [], {}, value
    if status == "error":
        return value, {}, None
    return value[0], value[1], None


def score_pair_task(
    identifier: str,
    ds,
    quick: bool = False,
    factory: Callable[[str], Any] | None = None,
    seeds: Sequence[int] | None = None,
) -> tuple[list[dict[str, Any]], dict[str, np.ndarray], dict[str, str] | None]:
    """One pair as a task: (rows, free-run predictions, skip entry or None). A ConfigError is a skip; any
    other exception of the identifier is a result (rows with status error), not a crashed run."""
    return _outcome(
        *_guarded(identifier, ds, lambda: score_pair(identifier, ds, quick=quick, factory=factory, seeds=seeds))
    )


def score_seed_task(
    identifier: str, ds, quick: bool, factory: Callable[[str], Any] | None, seeds: Sequence[int] | None, k: int
) -> tuple[str, Any]:
    """One training seed of one pair as a task (the unit the executor spreads: a pair's seeds run in parallel);
    ``(status, value)`` as :func:`_guarded`, with the seed's evaluations (or None) when it ran."""
    from sysid._blas import blas_threads

    with blas_threads(1):
        return _guarded(identifier, ds, lambda: _fit_seed(identifier, ds, quick, factory, None, seeds, k))


def _pair_outcome(identifier, ds, quick, results: list[tuple[str, Any]], seeds: Sequence[int] | None = None):
    """A pair's (rows, predictions, skip) from its seed tasks, as :func:`score_pair_task` gives it: the first
    failing seed (in seed order) decides a skip or an error."""
    for status, value in results:
        if status != "ok":
            return _outcome(status, value)
    return _outcome(
        *_guarded(identifier, ds, lambda: _assemble(identifier, ds, quick, None, [v for _, v in results], seeds))
    )


def score(
    identifiers: Iterable[str] | None = None,
    datasets: Iterable[str] | None = None,
    quick: bool = False,
    sysidentpy: bool = True,
    progress: bool = False,
    factory: Callable[[str], Any] | None = None,
    log: Callable[[str], None] | None = None,
    seeds: Sequence[int] | None = None,
    executor=None,
) -> ScoreRun:
    """Score identifiers × datasets. Unavailable identifiers/datasets are skipped with the reason.

    ``executor`` (:class:`benchmarks.execution.Executor`; default in-process) runs the pairs. BLAS runs
    single-threaded throughout (here and in :func:`score_pair`, wherever a pair runs; torch's training already
    does, :mod:`sysid.neural.device`), so the numbers do not depend on ``OPENBLAS_NUM_THREADS`` or the core count."""
    from sysid._blas import blas_threads

    with blas_threads(1):
        return _score(identifiers, datasets, quick, sysidentpy, progress, factory, log, seeds, executor)


def _score(identifiers, datasets, quick, sysidentpy, progress, factory, log, seeds=None, executor=None) -> ScoreRun:
    from benchmarks.datasets import list_datasets, load_dataset
    from sysid.registry import IDENTIFIERS, available_identifiers

    t_start = time.perf_counter()
    run = ScoreRun(quick=quick, environment=environment())
    log = log or (lambda s: None)
    chosen_here = identifiers is None
    if identifiers is None:
        identifiers = available_identifiers() if factory is None else list(IDENTIFIERS)
        for missing in sorted(set(IDENTIFIERS) - set(identifiers)):
            run.skipped.append({"identifier": missing, "reason": "not built yet (module not importable)"})
        if quick:
            for slow in [i for i in identifiers if i in QUICK_SKIP_IDENTIFIERS]:
                identifiers.remove(slow)
                run.skipped.append({"identifier": slow, "reason": QUICK_SKIP_IDENTIFIERS[slow]})
    identifiers = list(identifiers)
    if datasets is None:
        info = {d["id"]: d for d in list_datasets()}
        datasets = [n for n in (QUICK_DATASETS if quick else info) if info[n]["available"]]
        for n, d in info.items():
            if not d["available"] and (not quick or n in QUICK_DATASETS):
                run.skipped.append({"dataset": n, "reason": d["description"].rsplit("[", 1)[-1].rstrip("]")})
    datasets = list(datasets)
    run.selection = {"identifiers": identifiers, "datasets": datasets}
    loaded: dict[str, Any] = {}
    for dname in datasets:
        try:
            loaded[dname] = prepare_dataset(load_dataset(dname, progress=progress), quick)
        except InputError as exc:
            loaded[dname] = exc
    # Tasks run in-process or on Dask workers (benchmarks.execution); the rows are put together below in the
    # serial order, whatever order the tasks finished in.
    from benchmarks.execution import Executor

    ex = executor or Executor()
    handles = {d: ex.share(ds) for d, ds in loaded.items() if not isinstance(ds, Exception)}
    pairs = [(i, d) for d in datasets if d in handles for i in identifiers]
    if chosen_here:  # the default runs score some identifiers on some datasets only
        only = QUICK_ONLY_DATASETS if quick else FULL_ONLY_DATASETS
        left = [(i, d) for i, d in pairs if i in only and d not in only[i]["datasets"]]
        run.skipped.extend({"identifier": i, "dataset": d, "reason": only[i]["why"]} for i, d in left)
        pairs = [p for p in pairs if p not in left]

    # One task per training seed of a pair, so that the five seeds of a neural pair spread over the workers
    # instead of making one long task; the pair's rows are assembled here when its last seed is in.
    n_seeds = _max_seeds(quick, seeds)
    tasks = [(i, handles[d], quick, factory, seeds, k) for i, d in pairs for k in range(n_seeds)]
    pending: dict[tuple[str, str], dict[int, tuple[str, Any]]] = {p: {} for p in pairs}
    by_pair: dict[tuple[str, str], Any] = {}

    def collect(j: int, result: tuple[str, Any]) -> None:
        pair = pairs[j // n_seeds]
        pending[pair][j % n_seeds] = result
        if len(pending[pair]) == n_seeds:
            got = pending.pop(pair)
            ordered = [got[k] for k in range(n_seeds)]
            by_pair[pair] = _pair_outcome(pair[0], loaded[pair[1]], quick, ordered, seeds)
            for r in by_pair[pair][0]:
                log(format_row(r))

    # Larger estimation data first on a cluster (a proxy of a task's cost), so small tasks fill the end.
    size = {d: sum(len(r) for r in loaded[d].est_records) for d in handles}
    ex.map(
        score_seed_task,
        tasks,
        desc="score",
        progress=progress,
        on_result=collect,
        keep=False,
        priorities=[size[d] for _, d in pairs for _ in range(n_seeds)],
    )
    for dname in datasets:
        ds = loaded[dname]
        if isinstance(ds, Exception):
            run.skipped.append({"dataset": dname, "reason": str(ds)})
            continue
        run.datasets[dname] = ds
        for ident in identifiers:
            if (ident, dname) not in by_pair:
                continue  # left out of the quick run above, listed under skipped
            rows, preds, skip = by_pair[(ident, dname)]
            if skip is not None:
                run.skipped.append(skip)
            run.rows.extend(rows)
            for t, y in preds.items():
                run.predictions[(ident, dname, t)] = y
        if sysidentpy:
            from benchmarks.scoring.crosscheck import sysidentpy_frols

            run.sysidentpy.extend(sysidentpy_frols(ds, quick=quick))
    run.seconds = time.perf_counter() - t_start
    return run


def format_row(r: dict[str, Any]) -> str:
    head = f"{r['identifier']:<12} {r['dataset']:<20} {r['test']:<22}"
    if r.get("status") == "error":
        return f"{head} error: {r.get('message', '')}"
    fr, os_ = r["free_run"], r["one_step"]
    return (
        f"{head} free-run RMSE {_fmt(fr['rmse'])} {r['units']} (R2 {_fmt(fr['r2'])})  one-step RMSE "
        f"{_fmt(os_['rmse'])}  fit {r['fit_seconds']:.2f} s  {r['n_parameters']} params"
    )


def _fmt(x: Any) -> str:
    return "nan" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.4g}"


def _finite(x: Any) -> TypeGuard[float]:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
