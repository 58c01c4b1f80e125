"""Scoring: identifiers × datasets → test accuracy, fit time, parameter count; baselines that fail on regression.

One module per concern, every public name importable from here:

- :mod:`~benchmarks.scoring.settings`: the settings of each identifier on each dataset and of the quick check, read
  from the TOML files of ``benchmarks/settings/`` (:func:`settings_for`, :data:`SETTINGS`, :data:`QUICK_SEEDS` ...);
- :mod:`~benchmarks.scoring.core`: fitting and scoring the pairs (:func:`score`, :func:`score_pair`,
  :func:`evaluate`, :class:`ScoreRun`);
- :mod:`~benchmarks.scoring.crosscheck`: SysIdentPy's FROLS on the same split (:func:`sysidentpy_frols`);
- :mod:`~benchmarks.scoring.floors`: the floors of ``benchmarks/baselines.json`` and the regression check
  (:func:`check`, :func:`check_rules`, :func:`make_floors`, :func:`load_baselines`);
- :mod:`~benchmarks.scoring.report`: the markdown table and the report directory (:func:`write_report`).
"""

from __future__ import annotations

from benchmarks.scoring.core import (
    METRICS,
    ScoreRun,
    environment,
    evaluate,
    format_row,
    prepare_dataset,
    score,
    score_pair,
    score_pair_task,
    strip_timing,
)
from benchmarks.scoring.core import _finite as _finite
from benchmarks.scoring.core import _fmt as _fmt
from benchmarks.scoring.crosscheck import sysidentpy_frols
from benchmarks.scoring.floors import (
    BASELINES_FORMAT,
    BASELINES_PATH,
    DEFAULT_MARGIN,
    LINEAR_IDENTIFIERS,
    SEEDED_MARGIN,
    check,
    check_rules,
    dropped_pairs,
    load_baselines,
    make_floors,
    unfloored,
    version_mismatch,
)
from benchmarks.scoring.report import markdown_table, write_report
from benchmarks.scoring.settings import (
    FULL_ONLY_DATASETS,
    NORMALISE,
    QUICK_DATASETS,
    QUICK_MAX_SAMPLES,
    QUICK_ONLY_DATASETS,
    QUICK_SEEDS,
    QUICK_SETTINGS,
    QUICK_SKIP_IDENTIFIERS,
    QUICK_SKIP_TESTS,
    SETTINGS,
    SETTINGS_DIR,
    SYSIDENTPY_QUICK_MAX_EST,
    SYSIDENTPY_SETTINGS,
    is_seeded,
    load_identifier_settings,
    seeds_for,
    settings_for,
    sysidentpy_settings,
)
from sysid.data.jsonio import clean_json
from sysid.data.record import NormalisedModel, Record
from sysid.errors import ConfigError, InputError

_clean = clean_json  # the run as plain JSON (NaN/inf as null), as the CLI prints it
#: the former name of :class:`sysid.data.record.NormalisedModel` (an identifier fitted on normalised data)
Normalised = NormalisedModel

__all__ = [
    "BASELINES_FORMAT",
    "BASELINES_PATH",
    "DEFAULT_MARGIN",
    "LINEAR_IDENTIFIERS",
    "METRICS",
    "NORMALISE",
    "QUICK_DATASETS",
    "QUICK_MAX_SAMPLES",
    "QUICK_SEEDS",
    "FULL_ONLY_DATASETS",
    "QUICK_ONLY_DATASETS",
    "QUICK_SETTINGS",
    "QUICK_SKIP_IDENTIFIERS",
    "QUICK_SKIP_TESTS",
    "SEEDED_MARGIN",
    "SETTINGS",
    "SETTINGS_DIR",
    "SYSIDENTPY_QUICK_MAX_EST",
    "SYSIDENTPY_SETTINGS",
    "ConfigError",
    "InputError",
    "Normalised",
    "NormalisedModel",
    "Record",
    "ScoreRun",
    "check",
    "check_rules",
    "dropped_pairs",
    "environment",
    "evaluate",
    "format_row",
    "is_seeded",
    "load_baselines",
    "load_identifier_settings",
    "make_floors",
    "markdown_table",
    "prepare_dataset",
    "score",
    "score_pair",
    "score_pair_task",
    "seeds_for",
    "settings_for",
    "strip_timing",
    "sysidentpy_frols",
    "sysidentpy_settings",
    "unfloored",
    "version_mismatch",
    "write_report",
]
