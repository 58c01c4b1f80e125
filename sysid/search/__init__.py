"""Structure sweeps with repeated runs (dissertation Tables 4.2, 5.4–5.6 and Fig. 5.13), on Optuna.

A sweep tunes one identifier of :mod:`sysid.registry` (``piezotwin search``), neural or not: it tries
configurations (lags, layers, widths, activation …), fits each ``repeats`` times with seeds ``seed, seed+1, …``,
scores every run by R² one-step and free-run on the estimation and validation data, and reports per
configuration the mean and SD of the four R² values and the parameter count.

Grid SPEC (``--grid``): ``KEY=V1,V2,...`` items separated by ``;``, keys being the identifier's ``--set`` options;
a list value is written with dashes (``hidden=25-25,25-25-25-25`` gives two choices); ``a..b`` expands to every
integer from a to b; ``lags`` sets ``ny`` and ``nu`` together (``n_enc`` for ``rnn``)::

    lags=5,10;hidden=25-25,25-25-25-25;activation=relu,tanh

Samplers: ``grid`` (every combination), ``random`` and ``tpe`` (Optuna's Tree-structured Parzen Estimator) draw
``trials`` distinct configurations. One Optuna trial is one configuration with all its repeats. Storage: an
SQLite file by default, or ``postgresql://...`` for workers on several machines; re-running the same command
resumes (trials of a killed worker are found by Optuna's heartbeat and run again). The definition and single
runs live in :mod:`~sysid.search.sweep`, results (and their JSON-lines export) in
:mod:`~sysid.search.sweep_results`, the study's workers in :mod:`~sysid.search.study` (repeats as Dask tasks
through ``run_config(..., executor)``).
May import: :mod:`sysid.errors`, :mod:`sysid.config`, :mod:`sysid.progress`, :mod:`sysid.data`,
:mod:`sysid.evaluation`, :mod:`sysid.report`, :mod:`sysid.neural` (threads), :mod:`sysid.registry` (by name).
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
