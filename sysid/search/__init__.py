"""Structure sweeps with repeated runs (dissertation Tables 4.2, 5.4–5.6 and Fig. 5.13), on Optuna.

The package tunes any identifier of :mod:`sysid.registry` (``piezotwin search``), neural or not. A sweep tries
configurations of one identifier (lags, layers, widths, activation …), fits each ``repeats`` times with seeds
``seed, seed+1, …`` and scores every run by R² one-step and free-run on the estimation and validation data. Per
configuration it reports mean and SD of the four R² values and the parameter count.

Grid SPEC (``--grid``): ``KEY=V1,V2,...`` items separated by ``;``. Keys are constructor options of the
identifier (``piezotwin identify`` ``--set`` names); a list value is written with dashes as in ``--set``
(``hidden=25-25,25-25-25-25`` gives two choices); an integer range ``a..b`` expands to every integer from a
to b; the key ``lags`` sets ``ny`` and ``nu`` together (``n_enc`` for ``rnn``). Example::

    lags=5,10;hidden=25-25,25-25-25-25;activation=relu,tanh

Samplers: ``grid`` (every combination; workers claim configurations one at a time), ``random`` and ``tpe``
(Bayesian, Optuna's Tree-structured Parzen Estimator) draw ``trials`` distinct configurations from the same
choices. One Optuna trial is one configuration with all its repeats (per-run results in the trial's user
attributes).

Storage: an Optuna storage URL — by default an SQLite file; ``postgresql://user:pw@host/db`` lets workers on
several machines share one study. Re-running the same command resumes: finished configurations are kept,
configurations whose trial failed or was interrupted run again (trials of a killed worker are detected by
Optuna's heartbeat and retried). ``workers`` local processes share the storage; a progress bar shows the
configurations done and the time left. Results export as JSON lines (one line per run).

How many processes share one study and finish exactly the requested configurations, none twice, none lost to
a killed process: :mod:`sysid.search.study`. The repeats of a configuration can run as Dask tasks
(``run_config(..., executor)``, :mod:`benchmarks.execution`).

This module gathers the public names: the sweep's definition, storage and single runs live in
:mod:`sysid.search.sweep`, reading results back in :mod:`sysid.search.sweep_results`, and :func:`run_sweep` in
:mod:`sysid.search.study`.
"""

from sysid.search.study import run_sweep
from sysid.search.sweep import (
    DIVERGED_OBJECTIVE,
    R2_KEYS,
    SAMPLERS,
    SweepSpec,
    _open_storage,
    config_key,
    open_study,
    parse_grid,
    run_config,
    run_one,
    storage_url,
)
from sysid.search.sweep_results import collect, export_jsonl, plot_r2_distribution, summarise

__all__ = [
    "SweepSpec",
    "parse_grid",
    "storage_url",
    "run_sweep",
    "collect",
    "summarise",
    "export_jsonl",
    "plot_r2_distribution",
    "config_key",
    "open_study",
    "run_one",
    "run_config",
    "SAMPLERS",
    "R2_KEYS",
    "DIVERGED_OBJECTIVE",
    "_open_storage",
]
