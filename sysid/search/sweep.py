"""One structure sweep's definition and its single steps: the grid SPEC (:func:`parse_grid`, :class:`SweepSpec`),
the Optuna storage and study (:func:`storage_url`, :func:`open_study`), fitting one configuration's repeats
(:func:`run_one`, :func:`run_config`) and the trial objective.

What a sweep is and how SPEC is written: :mod:`sysid.search`; how several processes share one study:
:mod:`sysid.search.study` (which passes its claim rule down to :func:`_make_objective`).
"""

from __future__ import annotations

import json
import math
import os
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sysid.config import ALIASES, coerce, resolve_aliases
from sysid.data.record import Record
from sysid.errors import ConfigError
from sysid.search.folds import evaluate_folds, fit_scored

__all__ = [
    "SweepSpec",
    "parse_grid",
    "config_key",
    "storage_url",
    "heartbeat_settings",
    "open_study",
    "run_one",
    "run_config",
]

SAMPLERS = ("grid", "random", "tpe")
R2_KEYS = (
    ("estimation", "one_step"),
    ("estimation", "free_run"),
    ("validation", "one_step"),
    ("validation", "free_run"),
)
DIVERGED_OBJECTIVE = -1.0  # a diverged validation free run counts as R² = -1 in the objective only


# ---------------------------------------------------------------------------------------------- spec
def _identifier_defaults(identifier: str) -> dict[str, Any]:
    import inspect

    from sysid.registry import get_identifier

    cls = get_identifier(identifier)
    sig = inspect.signature(cls.__init__)
    return {
        p.name: p.default for p in sig.parameters.values() if p.name != "self" and p.kind is p.POSITIONAL_OR_KEYWORD
    }


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
    folds: int = 0  # 0: score on the validation record; K ≥ 2: blocked K-fold cross-validation (:mod:`.folds`)

    def __post_init__(self) -> None:
        if self.sampler not in SAMPLERS:
            raise ConfigError(f"--sampler {self.sampler!r} not one of: {', '.join(SAMPLERS)}")
        if not isinstance(self.repeats, int) or self.repeats < 1:
            raise ConfigError(f"--repeats must be a positive integer, got {self.repeats!r}")
        if isinstance(self.folds, bool) or not isinstance(self.folds, int) or (self.folds != 0 and self.folds < 2):
            raise ConfigError(f"--folds must be an integer of at least 2, got {self.folds!r}")
        defaults = _identifier_defaults(self.identifier)
        self.fixed = resolve_aliases(self.fixed, defaults, "--set")
        for k in self.fixed:
            if k not in defaults:
                raise ConfigError(
                    f"--set: unknown option {k!r} of {self.identifier}; valid: {', '.join(sorted(defaults))}"
                )
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


def heartbeat_settings() -> tuple[int, int]:
    """(heartbeat interval, grace period) in whole seconds (Optuna wants integers)."""
    try:
        beat = max(1, int(float(os.environ.get("PIEZOTWIN_HEARTBEAT_S", "20"))))
        grace = max(beat + 1, int(float(os.environ.get("PIEZOTWIN_GRACE_S", str(3 * beat)))))
    except ValueError as exc:
        raise ConfigError(f"PIEZOTWIN_HEARTBEAT_S / PIEZOTWIN_GRACE_S: {exc}") from None
    return beat, grace


def _retried(
    call: Callable[[], Any], errors: tuple[type[BaseException], ...], attempts: int = 10, pause_s: float = 0.2
) -> Any:
    """``call()``, called again while it raises one of ``errors``, after pauses of ``pause_s``, 2 ``pause_s``, …
    (at most ``attempts`` calls; the last error propagates). For the races of processes that create the same new
    store or study at once: the loser of a race succeeds once the winner is done."""
    for attempt in range(attempts):
        try:
            return call()
        except errors:
            if attempt == attempts - 1:
                raise
            time.sleep(pause_s * (attempt + 1))


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
        beat, grace = heartbeat_settings()
        # Two processes opening a new store at once race on creating its tables / version row: the loser gets
        # an IntegrityError ('UNIQUE constraint failed: alembic_version') or 'database is locked'; retry.
        from sqlalchemy.exc import SQLAlchemyError

        return _retried(
            lambda: storages.RDBStorage(url, heartbeat_interval=beat, grace_period=grace, **kwargs), (SQLAlchemyError,)
        )


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
    if not d["folds"]:
        d.pop("folds")  # a validation-record sweep's spec as stored before folds existed: its studies resume
    return d


def _create_study(storage, study_name: str, spec: SweepSpec):
    """create_study(load_if_exists=True), retried: two processes creating the same new store or study at once
    race on its tables and its name (an IntegrityError / DuplicatedStudyError / 'database is locked' in one)."""
    import optuna
    from sqlalchemy.exc import SQLAlchemyError

    return _retried(
        lambda: optuna.create_study(
            study_name=study_name,
            storage=storage,
            sampler=_make_sampler(spec),
            direction="maximize",
            load_if_exists=True,
        ),
        (optuna.exceptions.DuplicatedStudyError, SQLAlchemyError),
    )


def open_study(spec: SweepSpec, url: str, study_name: str, create: bool = True):
    import optuna

    storage = _open_storage(url)
    if create:
        study = _create_study(storage, study_name, spec)
        saved = study.user_attrs.get("spec")
        if saved is None:
            study.set_user_attr("spec", _spec_dict(spec))
        elif saved != json.loads(json.dumps(_spec_dict(spec))):
            raise ConfigError(
                f"study {study_name!r} in {url} was made with another sweep ({saved}); use another --study"
            )
        return study
    return optuna.load_study(study_name=study_name, storage=storage, sampler=_make_sampler(spec))


# ---------------------------------------------------------------------------------------------- one configuration
def run_one(
    spec: SweepSpec,
    config: dict[str, str],
    repeat: int,
    est: Record | Sequence[Record],
    val: Record | Sequence[Record] | None,
) -> dict[str, Any]:
    """Fit one run (repeat ``repeat``, seed ``spec.seed + repeat``) of one configuration: a pure function of
    its arguments, so a Dask worker gives the same numbers as this process. With ``spec.folds`` the run is the
    blocked cross-validation of :func:`sysid.search.folds.evaluate_folds` on ``est`` (``val`` unused)."""
    from sysid.registry import get_identifier

    seed = spec.seed + repeat
    cls = get_identifier(spec.identifier)

    def make_model():
        return cls.from_assignments(spec.assignments(config, seed))

    out: dict[str, Any] = {"config": dict(config), "repeat": repeat, "seed": seed}
    if spec.folds:
        rec = est[0] if not isinstance(est, Record) and len(est) == 1 else est
        if not isinstance(rec, Record):
            raise ConfigError("--folds cross-validates one estimation record; give one --est")
        scored = evaluate_folds(make_model, rec, spec.folds)
    elif val is None:
        raise ConfigError("a sweep without --folds needs a validation record (--val)")
    else:
        scored = fit_scored(make_model(), est, val)
    return {**out, **scored, "pid": os.getpid()}


def run_config(
    spec: SweepSpec,
    config: dict[str, str],
    est: Record | Sequence[Record],
    val: Record | Sequence[Record] | None,
    executor=None,
) -> list[dict[str, Any]]:
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


def _make_objective(
    spec: SweepSpec,
    est,
    val,
    claim: Callable[[Any, str, int], str | None],
    target: int | None = None,
    executor=None,
    state: dict[str, Any] | None = None,
) -> Callable:
    """The trial: ``claim(trial, key, target)`` the configuration (the coordination of the processes sharing
    the study passes its rule in: :func:`sysid.search.study.claim`), then fit its repeats."""
    import optuna

    state = {} if state is None else state
    limit = spec.n_configs if target is None else target

    def objective(trial: optuna.Trial) -> float:
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
