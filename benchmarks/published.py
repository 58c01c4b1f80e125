"""Published results, as data: ``benchmarks/settings/published.toml`` (every published number the project compares
with, each with its source and where this project read it).

- :func:`references` gives the reference numbers per dataset, test and kind (``linear_baseline``,
  ``best_published``, ...) in the dataset's units, for the scoring rows (:mod:`benchmarks.datasets.references`);
- :func:`best_published` gives the best published result of one test with its source, for the records table;
- :func:`baselines_table` puts the ten baselines of Champneys et al. 2024 beside the project's identifier of the
  same family, scored as the full check scores it (the measurements stored with the full floors in
  ``benchmarks/baselines.json``).

A number that was not read from its source is absent from the file, never guessed: the table says "not read".
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path
from typing import Any

from sysid.errors import ConfigError

PUBLISHED_PATH = Path(__file__).resolve().parent / "settings" / "published.toml"
#: units a published number may be printed in -> (the dataset's unit, factor to it)
UNITS: dict[str, tuple[str, float]] = {"V": ("V", 1.0), "mV": ("V", 1e-3), "m": ("m", 1.0), "um": ("um", 1.0)}
KINDS = ("linear_baseline", "best_published", "best_published_black_box", "best_published_grey_box", "sysidentpy")
_ENTRY_KEYS = {"value", "unit", "model", "source", "read_from"}


def load(path: str | Path | None = None) -> dict[str, Any]:
    """The published-results file, checked: every number finite and positive in a known unit, every source and
    ``read_from`` named in the file, every baseline family's identifier a known one. Bad file -> ConfigError."""
    import tomllib

    p = Path(path) if path else PUBLISHED_PATH
    try:
        with open(p, "rb") as fh:
            doc = tomllib.load(fh)
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise ConfigError(f"{p}: published results cannot be read ({exc})") from None
    _validate(doc, p)
    return doc


def _validate(doc: dict[str, Any], p: Path) -> None:
    from sysid.registry import IDENTIFIERS

    sources, read_from = doc.get("sources", {}), doc.get("read_from", {})
    for key, src in sources.items():
        if not (isinstance(src, dict) and src.get("short") and src.get("cite")):
            raise ConfigError(f"{p}: sources.{key} needs `short` and `cite`")
        if src.get("collected_in") not in (None, *sources):
            raise ConfigError(f"{p}: sources.{key}: collected_in {src['collected_in']!r} is not a source")
    for dname, tests in doc.get("references", {}).items():
        for test, kinds in tests.items():
            for kind, e in kinds.items():
                where = f"{p}: references.{dname}.{test}.{kind}"
                if kind not in KINDS:
                    raise ConfigError(f"{where}: unknown kind; valid: {', '.join(KINDS)}")
                if set(e) != _ENTRY_KEYS:
                    raise ConfigError(f"{where}: needs exactly {sorted(_ENTRY_KEYS)}")
                _check_number(e["value"], e["unit"], where)
                if e["source"] not in sources or e["read_from"] not in read_from:
                    raise ConfigError(f"{where}: source {e['source']!r} / read_from {e['read_from']!r} not defined")
    base = doc.get("baselines", {})
    if base:
        if base.get("source") not in sources:
            raise ConfigError(f"{p}: baselines.source {base.get('source')!r} is not in [sources]")
        names = [f["name"] for f in base.get("families", [])]
        for f in base.get("families", []):
            if f.get("identifier") and f["identifier"] not in IDENTIFIERS:
                raise ConfigError(f"{p}: baselines family {f['name']!r}: unknown identifier {f['identifier']!r}")
        tests = {(t["dataset"], t["test"]) for t in base.get("tests", [])}
        for dname, by_test in base.get("values", {}).items():
            for test, vals in by_test.items():
                where = f"{p}: baselines.values.{dname}.{test}"
                if (dname, test) not in tests:
                    raise ConfigError(f"{where}: not one of baselines.tests")
                unit = vals.get("unit")
                for name, v in vals.items():
                    if name in ("unit", "read_from"):
                        continue
                    if name not in names:
                        raise ConfigError(f"{where}: {name!r} is not a baseline family ({', '.join(names)})")
                    _check_number(v, unit, f"{where}.{name}")
                if vals.get("read_from") not in (None, *read_from):
                    raise ConfigError(f"{where}: read_from {vals.get('read_from')!r} not defined")


def _check_number(value: Any, unit: Any, where: str) -> None:
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
        raise ConfigError(f"{where}: value must be a finite positive number, got {value!r}")
    if unit not in UNITS:
        raise ConfigError(f"{where}: unit {unit!r} unknown; valid: {', '.join(UNITS)}")


def to_dataset_unit(value: float, unit: str) -> tuple[float, str]:
    """A published number in the dataset's unit (mV -> V)."""
    target, factor = UNITS[unit]
    return float(f"{value * factor:.12g}"), target  # 0.26 mV -> 0.00026 V, not 0.00026000000000000003


@lru_cache(maxsize=1)
def _shipped() -> dict[str, Any]:
    return load()


def references(doc: dict[str, Any] | None = None) -> dict[str, dict[str, dict[str, dict[str, Any]]]]:
    """dataset -> test -> kind -> {value (dataset's unit), unit, model}: the scoring rows' references (the sources
    are in the file and on the records page, not repeated in every scored row)."""
    doc = doc if doc is not None else _shipped()
    out: dict[str, dict[str, dict[str, dict[str, Any]]]] = {}
    for dname, tests in doc.get("references", {}).items():
        for test, kinds in tests.items():
            for kind, e in kinds.items():
                value, unit = to_dataset_unit(e["value"], e["unit"])
                out.setdefault(dname, {}).setdefault(test, {})[kind] = {
                    "value": value,
                    "unit": unit,
                    "model": e["model"],
                }
    return out


def source_text(key: str, doc: dict[str, Any] | None = None, short: bool = False) -> str:
    """A source with the collection it was read from: ``Paduart et al. 2010 in Champneys et al. 2024`` (``short``),
    else the full citations (``J. Paduart et al., 2010: ... (as collected in M. D. Champneys, ...)``)."""
    doc = doc if doc is not None else _shipped()
    src = doc["sources"][key]
    coll = src.get("collected_in")
    if short:
        return src["short"] + (f" in {doc['sources'][coll]['short']}" if coll else "")
    return src["cite"] + (f" (as collected in {doc['sources'][coll]['cite']})" if coll else "")


def best_published(dataset: str, test: str, doc: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """The best published result on one test as printed (value, unit, model), its source (``source``: short,
    ``cite``: in full) and where this project read it (``read_from``)."""
    doc = doc if doc is not None else _shipped()
    e = doc.get("references", {}).get(dataset, {}).get(test, {}).get("best_published")
    if e is None:
        return None
    return {
        "value": e["value"],
        "unit": e["unit"],
        "model": e["model"],
        "source": source_text(e["source"], doc, short=True),
        "cite": source_text(e["source"], doc),
        "read_from": doc["read_from"][e["read_from"]],
    }


def baselines_table(floors: dict[str, Any], doc: dict[str, Any] | None = None) -> dict[str, Any]:
    """The paper's baselines beside the project's identifier of the same family, per test of ``baselines.tests``.

    Each row: the family, the project's identifier (``""``: none), and per test the paper's number in the dataset's
    unit (None: not read) and the project's free-run RMSE as stored with its full floor in ``benchmarks/baselines.json``
    (``floors``: that file's ``modes.full``; the worst and best over the runs that set the floor, training seed 0,
    scored from sample max(init window, model lags)); None where the project has no such measurement (no
    identifier of the family, an option other than the scoring settings', or no full floor for the pair)."""
    doc = doc if doc is not None else _shipped()
    base = doc.get("baselines", {})
    tests = [(t["dataset"], t["test"]) for t in base.get("tests", [])]
    values = base.get("values", {})
    rows = []
    for fam in base.get("families", []):
        ident, option = fam.get("identifier", ""), fam.get("option", "")
        cells = []
        for dname, test in tests:
            vals = values.get(dname, {}).get(test, {})
            paper = None
            if fam["name"] in vals:
                paper = to_dataset_unit(vals[fam["name"]], vals["unit"])[0]
            floor = floors.get(ident, {}).get(dname, {}).get(test) if ident and not option else None
            project = None
            if floor:
                worst = floor["measured"]
                project = {"worst": worst, "best": floor.get("measured_min", worst), "runs": floor.get("runs", 1)}
            cells.append(
                {"dataset": dname, "test": test, "unit": _dataset_unit(dname, doc), "paper": paper, "project": project}
            )
        rows.append(
            {"family": fam["name"], "identifier": ident, "option": option, "note": fam.get("note", ""), "cells": cells}
        )
    return {
        "source": source_text(base["source"], doc) if base else "",
        "short": source_text(base["source"], doc, short=True) if base else "",
        "url": doc.get("sources", {}).get(base.get("source", ""), {}).get("url", ""),
        "not_read": base.get("not_read", ""),
        "tests": tests,
        "rows": rows,
    }


def _dataset_unit(dataset: str, doc: dict[str, Any]) -> str:
    """The dataset's unit of y, as its published numbers convert to it ("" when none is published)."""
    for kinds in doc.get("references", {}).get(dataset, {}).values():
        for e in kinds.values():
            return UNITS[e["unit"]][0]
    return ""


def baselines_text(fmt, floors: dict[str, Any], doc: dict[str, Any] | None = None) -> dict[str, Any]:
    """:func:`baselines_table` with every cell as text ``paper · project``, figures by ``fmt(value, unit)``: the
    paper's number or "not read"; the project's (best-worst over the floor's runs when they differ), "not
    measured", or "no identifier of this family"."""
    table = baselines_table(floors, doc)
    rows = []
    for row in table["rows"]:
        cells = []
        for c in row["cells"]:
            unit, p = c["unit"], c["project"]
            paper = fmt(c["paper"], unit) if c["paper"] is not None else "not read"
            if not row["identifier"]:
                project = "—"
            elif p is None:
                project = "not measured"
            elif fmt(p["best"], unit) != fmt(p["worst"], unit):
                project = f"{fmt(p['best'], unit)}–{fmt(p['worst'], unit)}"
            else:
                project = fmt(p["worst"], unit)
            cells.append(f"{paper} · {project}")
        ident = f"`{row['identifier']}`" if row["identifier"] else "—"
        ident += f" ({row['option']})" if row["option"] else ""
        rows.append({"family": row["family"], "identifier": ident, "note": row["note"], "cells": cells})
    return {**table, "rows": rows, "tests": [f"{d} / {t}" for d, t in table["tests"]]}
