"""Structure sweeps with repeated runs (dissertation Tables 4.2, 5.4–5.6 and Fig. 5.13), on Optuna.

A sweep tries configurations of one identifier (lags, layers, widths, activation …), fits each ``repeats``
times with seeds ``seed, seed+1, …`` and scores every run by R² one-step and free-run on the estimation and
validation data. Per configuration it reports mean and SD of the four R² values and the parameter count.

Grid SPEC (``--grid``): ``KEY=V1,V2,...`` items separated by ``;``. Keys are constructor options of the
identifier (``piezotwin identify`` ``--set`` names); a list value is written with dashes as in ``--set``
(``hidden=25-25,25-25-25-25`` gives two choices); an integer range ``a..b`` expands to every integer from a
to b; the key ``lags`` sets ``ny`` and ``nu`` together (``n_enc`` for ``rnn``). Example::

    lags=5,10;hidden=25-25,25-25-25-25;activation=relu,tanh

Samplers: ``grid`` (every combination; workers claim configurations one at a time), ``random`` and ``tpe`` (Bayesian, Optuna's Tree-structured Parzen
Estimator) draw ``trials`` distinct configurations from the same choices. One Optuna trial is one
configuration with all its repeats (per-run results in the trial's user attributes).

Storage: an Optuna storage URL — by default an SQLite file; ``postgresql://user:pw@host/db`` lets workers on
several machines share one study. Re-running the same command resumes: finished configurations are kept,
configurations whose trial failed or was interrupted run again (trials of a killed worker are detected by
Optuna's heartbeat and retried). ``workers`` local processes share the storage; a progress bar shows the
configurations done and the time left. Results export as JSON lines (one line per run).

How many processes share one study and finish exactly the requested configurations, none twice, none lost to
a killed process: :mod:`sysid.neural.study`. The repeats of a configuration can run as Dask tasks
(``run_config(..., executor)``, :mod:`benchmarks.execution`).
"""

from __future__ import annotations

import json
import math
import os
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from sysid.config import ALIASES, coerce, resolve_aliases
from sysid.errors import ConfigError, DivergenceWarning
from sysid.record import Record

__all__ = ["SweepSpec", "parse_grid", "storage_url", "run_sweep", "collect", "summarise", "export_jsonl",
           "plot_r2_distribution"]

SAMPLERS = ("grid", "random", "tpe")
R2_KEYS = (("estimation", "one_step"), ("estimation", "free_run"), ("validation", "one_step"), ("validation", "free_run"))
DIVERGED_OBJECTIVE = -1.0  # a diverged validation free run counts as R² = -1 in the objective only


# ---------------------------------------------------------------------------------------------- spec
def _identifier_defaults(identifier: str) -> dict[str, Any]:
    import inspect

    from sysid.registry import get_identifier

    cls = get_identifier(identifier)
    sig = inspect.signature(cls.__init__)
    return {p.name: p.default for p in sig.parameters.values() if p.name != "self" and p.kind is p.POSITIONAL_OR_KEYWORD}


def parse_grid(spec: str, identifier: str) -> dict[str, list[str]]:
    """``"lags=5,10;hidden=25-25,50-50"`` → ``{"lags": ["5", "10"], "hidden": ["25-25", "50-50"]}`` (checked)."""
    defaults = _identifier_defaults(identifier)
    valid = sorted(defaults) + ["lags"]
    grid: dict[str, list[str]] = {}
    for item in str(spec or "").split(";"):
        item = item.strip()
        if not item:
            continue
        if "=" not in item:
            raise ConfigError(f"--grid: expected KEY=V1,V2,... got {item!r}")
        key, _, values = item.partition("=")
        key = key.strip()
        if key not in valid and ALIASES.get(key) in defaults:  # deprecated spelling (n_y, n_u, linear_order)
            key = next(iter(resolve_aliases({key: None}, defaults, "--grid")))
        if key not in valid:
            raise ConfigError(f"--grid: unknown option {key!r} of {identifier}; valid: {', '.join(valid)}")
        if key in grid:
            raise ConfigError(f"--grid: {key!r} given twice")
        choices: list[str] = []
        for v in values.split(","):
            v = v.strip()
            if not v:
                continue
            if ".." in v:
                a, _, b = v.partition("..")
                try:
                    lo, hi = int(a), int(b)
                except ValueError:
                    raise ConfigError(f"--grid: range {v!r} of {key} must be integers a..b") from None
                if hi < lo or hi - lo > 10_000:
                    raise ConfigError(f"--grid: range {v!r} of {key} is empty or too long")
                choices += [str(i) for i in range(lo, hi + 1)]
            else:
                choices.append(v)
        if not choices:
            raise ConfigError(f"--grid: no values for {key!r}")
        # type check every value now (a typo fails before hours of training, not in the middle)
        for v in choices:
            for target in _targets(key, identifier, defaults):
                coerce(v, defaults[target], target)
        grid[key] = list(dict.fromkeys(choices))
    if not grid:
        raise ConfigError("--grid: empty SPEC; e.g. lags=5,10;hidden=25-25,25-25-25-25;activation=relu,tanh")
    return grid


def _targets(key: str, identifier: str, defaults: dict[str, Any]) -> list[str]:
    if key != "lags":
        return [key]
    if "n_enc" in defaults and "ny" not in defaults:
        return ["n_enc"]
    if "ny" in defaults:  # every identifier with lags spells them ny, nu (sysid.config.ALIASES)
        return [k for k in ("ny", "nu") if k in defaults]
    raise ConfigError(f"--grid: {identifier} has no lag options for 'lags'")


@dataclass
class SweepSpec:
    identifier: str
    grid: dict[str, list[str]]
    repeats: int = 1
    seed: int = 0
    fixed: dict[str, str] = field(default_factory=dict)
    sampler: str = "grid"

    def __post_init__(self) -> None:
        if self.sampler not in SAMPLERS:
            raise ConfigError(f"--sampler {self.sampler!r} not one of: {', '.join(SAMPLERS)}")
        if not isinstance(self.repeats, int) or self.repeats < 1:
            raise ConfigError(f"--repeats must be a positive integer, got {self.repeats!r}")
        defaults = _identifier_defaults(self.identifier)
        self.fixed = resolve_aliases(self.fixed, defaults, "--set")
        for k in self.fixed:
            if k not in defaults:
                raise ConfigError(f"--set: unknown option {k!r} of {self.identifier}; valid: {', '.join(sorted(defaults))}")
            if k in self.grid or (k in ("n_enc", "ny", "nu") and "lags" in self.grid):
                raise ConfigError(f"--set {k} conflicts with the same option in --grid")
        if "seed" in self.grid:
            raise ConfigError("--grid: seed is set by --seed and --repeats, not swept")

    @property
    def n_configs(self) -> int:
        return int(np.prod([len(v) for v in self.grid.values()]))

    def assignments(self, config: dict[str, str], seed: int) -> dict[str, str]:
        defaults = _identifier_defaults(self.identifier)
        out = dict(self.fixed)
        for key, value in config.items():
            for target in _targets(key, self.identifier, defaults):
                out[target] = value
        if "seed" in defaults:
            out["seed"] = str(seed)
        return out


def config_key(config: dict[str, str]) -> str:
    return ";".join(f"{k}={config[k]}" for k in sorted(config))


# ---------------------------------------------------------------------------------------------- storage
def storage_url(storage: str | None, study: str) -> str:
    """A URL as given (``sqlite:///…``, ``postgresql://…``), or a file path → SQLite URL; None → ``STUDY.db``."""
    if not storage:
        storage = f"{study}.db"
    if "://" in storage:
        return storage
    return "sqlite:///" + str(Path(storage).expanduser().resolve())


def _open_storage(url: str):
    import inspect

    import optuna
    from optuna import storages

    kwargs: dict[str, Any] = {}
    if url.startswith("sqlite"):
        kwargs["engine_kwargs"] = {"connect_args": {"timeout": 120}}
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    # Trials of a killed worker stop sending heartbeats; after the grace period Optuna fails them and the
    # callback re-queues the same configuration (the name of that option changed in Optuna 4.9).
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
        if "heartbeat_stale_trial_callback" in inspect.signature(storages.RDBStorage.__init__).parameters:
            kwargs["heartbeat_stale_trial_callback"] = storages.RetryHeartbeatStaleTrialCallback(max_retry=2)
        else:  # pragma: no cover - older Optuna
            kwargs["failed_trial_callback"] = storages.RetryFailedTrialCallback(max_retry=2)
        from sysid.neural.study import heartbeat_settings

        beat, grace = heartbeat_settings()
        # Two processes opening a new store at once race on creating its tables / version row: the loser gets
        # an IntegrityError ('UNIQUE constraint failed: alembic_version') or 'database is locked'; retry.
        from sqlalchemy.exc import SQLAlchemyError

        for attempt in range(10):
            try:
                return storages.RDBStorage(url, heartbeat_interval=beat, grace_period=grace, **kwargs)
            except SQLAlchemyError:
                if attempt == 9:
                    raise
                time.sleep(0.2 * (attempt + 1))


def _make_sampler(spec: SweepSpec):
    import optuna

    if spec.sampler in ("grid", "random"):
        # grid: each worker fixes the next unclaimed configuration (PartialFixedSampler over this one), so the
        # sampler never draws; Optuna's GridSampler cannot rerun an interrupted grid point (its after_trial
        # needs a grid_id that re-queued trials lack).
        return optuna.samplers.RandomSampler(seed=spec.seed)
    return optuna.samplers.TPESampler(seed=spec.seed, n_startup_trials=5)


def _spec_dict(spec: SweepSpec) -> dict[str, Any]:
    d = asdict(spec)
    d.pop("sampler")  # a study may be continued with another sampler
    return d


def _create_study(storage, study_name: str, spec: SweepSpec):
    """create_study(load_if_exists=True), retried: two processes creating the same new store or study at once
    race on its tables and its name (an IntegrityError / DuplicatedStudyError / 'database is locked' in one)."""
    import optuna
    from sqlalchemy.exc import SQLAlchemyError

    for attempt in range(10):
        try:
            return optuna.create_study(study_name=study_name, storage=storage, sampler=_make_sampler(spec),
                                       direction="maximize", load_if_exists=True)
        except (optuna.exceptions.DuplicatedStudyError, SQLAlchemyError):
            if attempt == 9:
                raise
            time.sleep(0.2 * (attempt + 1))


def open_study(spec: SweepSpec, url: str, study_name: str, create: bool = True):
    import optuna

    storage = _open_storage(url)
    if create:
        study = _create_study(storage, study_name, spec)
        saved = study.user_attrs.get("spec")
        if saved is None:
            study.set_user_attr("spec", _spec_dict(spec))
        elif saved != json.loads(json.dumps(_spec_dict(spec))):
            raise ConfigError(f"study {study_name!r} in {url} was made with another sweep ({saved}); use another --study")
        return study
    return optuna.load_study(study_name=study_name, storage=storage, sampler=_make_sampler(spec))


# ---------------------------------------------------------------------------------------------- one configuration
def run_one(spec: SweepSpec, config: dict[str, str], repeat: int, est: Record | Sequence[Record],
            val: Record | Sequence[Record]) -> dict[str, Any]:
    """Fit one run (repeat ``repeat``, seed ``spec.seed + repeat``) of one configuration: a pure function of
    its arguments, so a Dask worker gives the same numbers as this process."""
    from sysid.evaluate import evaluate
    from sysid.registry import get_identifier

    seed = spec.seed + repeat
    model = get_identifier(spec.identifier).from_assignments(spec.assignments(config, seed))
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DivergenceWarning)
        model.fit(est)
    fit_s = time.perf_counter() - t0
    return {"config": dict(config), "repeat": repeat, "seed": seed, "n_parameters": model.n_parameters_,
            "fit_seconds": fit_s, "estimation": evaluate(model, est), "validation": evaluate(model, val),
            "pid": os.getpid()}


def run_config(spec: SweepSpec, config: dict[str, str], est: Record | Sequence[Record],
               val: Record | Sequence[Record], executor=None) -> list[dict[str, Any]]:
    """Fit ``spec.repeats`` models of one configuration; one dict per run with the identify-JSON scores.
    ``executor`` (:class:`benchmarks.execution.Executor`, or any object with its ``map``) runs the repeats;
    default: one after the other here. ``est``/``val`` may be handles of ``executor.share``."""
    tasks = [(spec, config, r, est, val) for r in range(spec.repeats)]
    if executor is None:
        return [run_one(*t) for t in tasks]
    return executor.map(run_one, tasks, desc=config_key(config), progress=False)


def _objective_value(runs: list[dict[str, Any]]) -> float:
    vals = [run["validation"]["free_run"]["r2"] for run in runs]
    vals = [DIVERGED_OBJECTIVE if v is None or not math.isfinite(v) else max(v, DIVERGED_OBJECTIVE) for v in vals]
    return float(np.mean(vals))


def _clean(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def _make_objective(spec: SweepSpec, est, val, target: int | None = None, executor=None,
                    state: dict[str, Any] | None = None) -> Callable:
    """The trial: claim the configuration (:func:`sysid.neural.study.claim`), then fit its repeats."""
    import optuna

    from sysid.neural.study import claim

    state = {} if state is None else state
    limit = spec.n_configs if target is None else target

    def objective(trial: "optuna.Trial") -> float:
        config = {k: trial.suggest_categorical(k, v) for k, v in spec.grid.items()}
        key = config_key(config)
        reason = claim(trial, key, limit)
        if reason is not None:
            state["clash"] = True
            raise optuna.TrialPruned(reason)  # not counted; the loop draws or picks again
        trial.set_user_attr("claimed", True)  # the claim stands: this trial fits the configuration
        try:
            runs = run_config(spec, config, est, val, executor=executor)
        except Exception as exc:
            trial.set_user_attr("error", f"{type(exc).__name__}: {exc}"[:300])
            state["failed_key"] = key
            raise
        trial.set_user_attr("runs", _clean(runs))
        return _objective_value(runs)

    return objective


def _grid_configs(spec: SweepSpec) -> list[dict[str, str]]:
    import itertools

    keys = list(spec.grid)
    return [dict(zip(keys, values)) for values in itertools.product(*(spec.grid[k] for k in keys))]


def _requeue_failed(study, spec: SweepSpec) -> int:
    """Resume: configurations whose trial failed (interrupted, error) and never completed run again."""
    from optuna.trial import TrialState

    trials = study.get_trials(deepcopy=False)
    done = {t.user_attrs.get("config_key") for t in trials if t.state == TrialState.COMPLETE}
    pending = {config_key({k: str(v) for k, v in t.params.items()}) for t in trials if t.state == TrialState.WAITING}
    n = 0
    for t in trials:
        if t.state != TrialState.FAIL or not t.params or set(t.params) != set(spec.grid):
            continue
        key = config_key({k: str(v) for k, v in t.params.items()})
        if key in done or key in pending:
            continue
        study.enqueue_trial(dict(t.params), skip_if_exists=False)
        pending.add(key)
        n += 1
    return n


def run_sweep(spec: SweepSpec, est: Record | Sequence[Record], val: Record | Sequence[Record], storage: str | None = None,
              study: str = "piezotwin-search", trials: int | None = None, workers: int = 1, progress: bool = True,
              executor=None) -> dict[str, Any]:
    """Run (or resume) a sweep until the study holds ``trials`` finished configurations (all by default);
    :func:`summarise` of the study plus ``requested``/``complete``/``missing``. See :mod:`sysid.neural.study`."""
    from sysid.neural.study import run_sweep as _run

    return _run(spec, est, val, storage=storage, study=study, trials=trials, workers=workers, progress=progress,
                executor=executor)


# ---------------------------------------------------------------------------------------------- results
def collect(url: str, study_name: str) -> list[dict[str, Any]]:
    """All finished runs of a study (one dict per run, first complete trial of each configuration)."""
    import optuna
    from optuna.trial import TrialState

    st = optuna.load_study(study_name=study_name, storage=_open_storage(url))
    seen: set[str] = set()
    runs: list[dict[str, Any]] = []
    for t in sorted(st.get_trials(deepcopy=False, states=(TrialState.COMPLETE,)), key=lambda t: t.number):
        key = t.user_attrs.get("config_key")
        if key is None or key in seen:
            continue
        seen.add(key)
        for run in t.user_attrs.get("runs", []):
            runs.append({"trial": t.number, "config_key": key, **run})
    return runs


def _stat(values: list[float | None]) -> tuple[float | None, float | None, int]:
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if v.size == 0:
        return None, None, 0
    return float(v.mean()), (float(v.std(ddof=1)) if v.size > 1 else 0.0), int(v.size)


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per configuration: mean/SD of R² (one-step / free-run × estimation / validation), parameters, runs.

    ``configs`` is ordered best first by mean validation free-run R² (Table 5.5 lists the same ascending);
    ``best_runs`` are the individual runs of the best configuration (Table 5.6 analogue).
    """
    by: dict[str, list[dict[str, Any]]] = {}
    for run in runs:
        by.setdefault(run["config_key"], []).append(run)
    configs = []
    for key, rs in by.items():
        entry: dict[str, Any] = {"config": rs[0]["config"], "config_key": key, "n_parameters": rs[0]["n_parameters"],
                                 "runs": len(rs), "fit_seconds_mean": float(np.mean([r["fit_seconds"] for r in rs]))}
        for part, mode in R2_KEYS:
            mean, sd, n_ok = _stat([r[part][mode]["r2"] for r in rs])
            tag = f"{'est' if part == 'estimation' else 'val'}_{'osa' if mode == 'one_step' else 'frs'}"
            entry[f"r2_{tag}_mean"] = mean
            entry[f"r2_{tag}_sd"] = sd
            if mode == "free_run":
                entry[f"diverged_{tag}"] = len(rs) - n_ok
        configs.append(entry)
    configs.sort(key=lambda e: -np.inf if e["r2_val_frs_mean"] is None else e["r2_val_frs_mean"], reverse=True)
    best = configs[0]["config_key"] if configs else None
    best_runs = sorted((r for r in runs if r["config_key"] == best),
                       key=lambda r: -np.inf if r["validation"]["free_run"]["r2"] is None else r["validation"]["free_run"]["r2"])
    return {"n_configs": len(configs), "n_runs": len(runs), "configs": configs,
            "best": configs[0] if configs else None,
            "best_runs": [{"repeat": r["repeat"], "seed": r["seed"],
                           "r2_est_osa": r["estimation"]["one_step"]["r2"], "r2_est_frs": r["estimation"]["free_run"]["r2"],
                           "r2_val_osa": r["validation"]["one_step"]["r2"], "r2_val_frs": r["validation"]["free_run"]["r2"]}
                          for r in best_runs]}


def export_jsonl(runs: list[dict[str, Any]], path: str | Path) -> Path:
    """One JSON object per run (config, seed, n_parameters, fit_seconds, estimation/validation scores)."""
    from sysid.safeio import atomic_write_text

    return atomic_write_text(path, "".join(json.dumps(_clean(run)) + "\n" for run in runs))


def plot_r2_distribution(runs: list[dict[str, Any]], config_key_: str, path: str | Path) -> Path:
    """Fig. 5.13 analogue: histograms of free-run R² in estimation and validation with fitted normal curves."""
    from sysid.plots import pyplot, save_and_close

    plt = pyplot()
    rs = [r for r in runs if r["config_key"] == config_key_]
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for ax, part, title in zip(axes, ("estimation", "validation"), ("(a) estimation", "(b) validation")):
        v = np.array([r[part]["free_run"]["r2"] for r in rs if r[part]["free_run"]["r2"] is not None], dtype=float)
        v = v[np.isfinite(v)]
        if v.size:
            ax.hist(v, bins=max(5, min(30, v.size // 2)), density=True, alpha=0.6)
            if v.size > 1 and v.std() > 0:
                x = np.linspace(v.min(), v.max(), 200)
                ax.plot(x, np.exp(-0.5 * ((x - v.mean()) / v.std(ddof=1)) ** 2) / (v.std(ddof=1) * np.sqrt(2 * np.pi)))
            ax.set_title(f"{title}: mean {v.mean():.4f}, SD {v.std(ddof=1) if v.size > 1 else 0:.4f}, {v.size} runs")
        ax.set_xlabel("free-run R²")
    fig.suptitle(config_key_)
    fig.tight_layout()
    return save_and_close(fig, path, dpi=110)
