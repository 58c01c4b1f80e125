"""Benchmark settings as data: what each identifier is fitted with on each dataset, and what the quick check runs.

The values live in TOML files under ``benchmarks/settings/`` (shipped with the package):

- ``identifiers/<identifier>.toml``: ``[datasets."*"]`` applies to every dataset, ``[datasets.<name>]`` overrides
  it for one dataset, and in quick mode ``[quick."*"]`` / ``[quick.<name>]`` override both. Every table carries a
  ``why`` line saying where its values come from; the other keys are the identifier's constructor options (the
  names of ``--set``), plus the scoring option :data:`NORMALISE`.
- ``quick.toml``: the datasets of the quick check, its sample budgets, the identifiers it leaves out (with the
  reason) and the training seeds of the seeded identifiers.
- ``sysidentpy.toml``: lags and degree of SysIdentPy's FROLS, the cross-check beside each row.

The files are read once, at import; the tables below are plain dicts in the files' order.
"""

from __future__ import annotations

import inspect
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sysid.errors import ConfigError

SETTINGS_DIR = Path(__file__).resolve().parent.parent / "settings"
#: scoring option in the settings (not an identifier option): fit on normalised data, metrics in the data's units
NORMALISE = "normalise"
# The accuracy measures of every scored row, one-step and free run (sysid.evaluation.metrics).
METRICS = ("rmse", "nrmse", "r2")


def _read(path: Path) -> dict[str, Any]:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{path}: benchmark settings cannot be read ({exc})") from None


def _tables(doc: dict[str, Any], part: str, path: Path) -> dict[str, dict[str, Any]]:
    """The ``[part.<dataset>]`` tables of one identifier file, each without its ``why`` line (which it must have)."""
    out = {}
    for dname, entry in doc.get(part, {}).items():
        options = dict(entry)
        why = options.pop("why", None)
        if not (isinstance(why, str) and why.strip()):
            raise ConfigError(f"{path}: [{part}.{dname}] needs a `why` line saying where its values come from")
        out[dname] = options
    return out


def load_identifier_settings(
    directory: Path | None = None,
) -> tuple[dict[str, dict[str, dict[str, Any]]], dict[str, dict[str, dict[str, Any]]]]:
    """(settings, quick overrides) per identifier and dataset, from ``identifiers/*.toml`` (by file name)."""
    settings: dict[str, dict[str, dict[str, Any]]] = {}
    quick: dict[str, dict[str, dict[str, Any]]] = {}
    for path in sorted((directory or SETTINGS_DIR / "identifiers").glob("*.toml")):
        doc = _read(path)
        unknown = set(doc) - {"datasets", "quick"}
        if unknown:
            raise ConfigError(f"{path}: unknown table(s) {sorted(unknown)}; expected [datasets.*] and [quick.*]")
        settings[path.stem] = _tables(doc, "datasets", path)
        if "quick" in doc:
            quick[path.stem] = _tables(doc, "quick", path)
    return settings, quick


# Identifier settings per dataset ("*" = every dataset) and their quick-mode overrides.
SETTINGS, QUICK_SETTINGS = load_identifier_settings()

_QUICK = _read(SETTINGS_DIR / "quick.toml")
#: datasets of the quick check (small or fast enough for CI)
QUICK_DATASETS: tuple[str, ...] = tuple(_QUICK["datasets"])
#: quick-mode sample budget per dataset: estimation data ("est") and tests ("test") are cut to their first samples
QUICK_MAX_SAMPLES: dict[str, dict[str, int]] = _QUICK.get("max_samples", {})
#: identifiers left out of the default quick run, with the reason (``--identifiers`` still runs them quick)
QUICK_SKIP_IDENTIFIERS: dict[str, str] = _QUICK.get("skip_identifiers", {})
#: identifiers that the default quick run scores on some datasets only: {identifier: {"datasets": [...], "why": ...}}
QUICK_ONLY_DATASETS: dict[str, dict[str, Any]] = _QUICK.get("only_datasets", {})
#: tests left out of the quick check per dataset, with the reason: {dataset: {"tests": [...], "why": ...}}
QUICK_SKIP_TESTS: dict[str, dict[str, Any]] = _QUICK.get("skip_tests", {})
_FULL = _read(SETTINGS_DIR / "full.toml")
#: identifiers that the default full run scores on some datasets only: {identifier: {"datasets": [...], "why": ...}}
FULL_ONLY_DATASETS: dict[str, dict[str, Any]] = _FULL.get("only_datasets", {})
#: training seeds of the seeded identifiers in quick mode, each test scored by the run of median free-run RMSE
QUICK_SEEDS: tuple[int, ...] = tuple(_QUICK["seeds"])

_SYSIDENTPY = _read(SETTINGS_DIR / "sysidentpy.toml")
#: SysIdentPy FROLS on the same split: lags and degree per dataset ("*" = every dataset)
SYSIDENTPY_SETTINGS: dict[str, dict[str, Any]] = _SYSIDENTPY["datasets"]
#: quick runs fit SysIdentPy only on estimation sets up to this size
SYSIDENTPY_QUICK_MAX_EST: int = _SYSIDENTPY["quick_max_est"]


def settings_for(identifier: str, dataset: str, quick: bool = False) -> dict[str, Any]:
    """The constructor options used for ``identifier`` on ``dataset``."""
    out: dict[str, Any] = {}
    for table in (SETTINGS, QUICK_SETTINGS) if quick else (SETTINGS,):
        entry = table.get(identifier, {})
        out.update(entry.get("*", {}))
        out.update(entry.get(dataset, {}))
    return out


def sysidentpy_settings(dataset: str) -> dict[str, Any]:
    """SysIdentPy's FROLS options for ``dataset``."""
    return {**SYSIDENTPY_SETTINGS["*"], **SYSIDENTPY_SETTINGS.get(dataset, {})}


def is_seeded(cls: Any) -> bool:
    """True when an identifier class takes a ``seed`` option (its fit is a random draw: neural training)."""
    try:
        return "seed" in inspect.signature(cls).parameters
    except (TypeError, ValueError):  # pragma: no cover - not introspectable
        return False


def seeds_for(
    cls: Any, params: dict[str, Any], quick: bool, seeds: Sequence[int] | None = None
) -> tuple[int | None, ...]:
    """Training seeds scored for one pair: for a seeded identifier whose settings fix no seed, ``seeds`` when
    given (quick or full mode), else :data:`QUICK_SEEDS` in quick mode; otherwise one run with the settings as
    given (``None``: a full run without ``seeds`` trains the identifier's default seed)."""
    if (quick or seeds is not None) and "seed" not in params and is_seeded(cls):
        return tuple(int(x) for x in (QUICK_SEEDS if seeds is None else seeds))
    return (None,)
