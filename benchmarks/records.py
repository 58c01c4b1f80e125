"""The records table: per dataset, the identifier whose full settings give its best row, scored over training
seeds, stored with how it was measured, and rendered into ``docs/benchmarks.md`` and ``benchmarks/records.json``.

- ``benchmarks/settings/records.toml`` names, per dataset, the identifier of its row (with a ``why`` line) and,
  optionally, ``beside``: other identifiers whose rows the table shows under it for comparison;
- :func:`measure` scores one row exactly as ``piezotwin score --datasets D --identifiers I --seeds A-B --json``
  does (same library call, same settings) and wraps the raw result with the machine, date, load average,
  package versions and wall/CPU seconds; :func:`write_row` stores it as ``<dataset>.json`` (atomically);
- :func:`load_rows` reads the stored rows back, :func:`summary` turns them into the ``records.json`` mapping and
  :func:`render_markdown` fills the page template (``benchmarks/templates/benchmarks.md.j2``).

Rendering needs no fitting, so one dataset's row can be measured again while the others are kept as stored.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from benchmarks.scoring.settings import SETTINGS_DIR, _read
from sysid.errors import ConfigError

ROW_FORMAT = "piezotwin-records-row/1"
_ROOT = Path(__file__).resolve().parent.parent
#: where the rows are stored, the page and the summary are written (a source checkout's paths)
STORED_DIR = _ROOT / "docs" / "records"
MARKDOWN_PATH = _ROOT / "docs" / "benchmarks.md"
RECORDS_JSON = Path(__file__).resolve().parent / "records.json"
RECORDS_SETTINGS = SETTINGS_DIR / "records.toml"
TEMPLATES_DIR = Path(__file__).resolve().parent / "templates"
TEMPLATE = "benchmarks.md.j2"
#: training seeds of every row (a deterministic identifier is fitted once and says so)
DEFAULT_SEEDS: tuple[int, ...] = (0, 1, 2)
# keys of a score run that measure time, not accuracy: they differ between two runs of the same command


@dataclass(frozen=True)
class Entry:
    """One row of the table: the dataset, the identifier whose full settings give it, and why that one.

    ``beside``: identifiers shown under the chosen row for comparison (each is an entry of its own, whose
    ``beside_of`` names the chosen identifier; :func:`beside_entries`)."""

    dataset: str
    identifier: str
    why: str
    beside: tuple[str, ...] = ()
    beside_of: str = ""

    @property
    def key(self) -> str:
        """Where the row is stored and found (:func:`row_key`)."""
        return row_key(self.dataset, self.identifier if self.beside_of else None)


def row_key(dataset: str, identifier: str | None = None) -> str:
    """``dataset`` for a chosen row, ``dataset--identifier`` for a row shown beside it: the stored file's stem and
    the key of :func:`load_rows`."""
    return f"{dataset}--{identifier}" if identifier else dataset


def load_entries(path: str | Path | None = None) -> list[Entry]:
    """The rows of ``records.toml`` in the file's order; each table needs a known ``identifier`` and a ``why``."""
    from benchmarks.datasets import dataset_names
    from sysid.registry import IDENTIFIERS

    path = Path(path) if path else RECORDS_SETTINGS
    entries = []
    for dname, table in _read(path).items():
        if dname not in dataset_names():
            raise ConfigError(f"{path}: [{dname}] is not a dataset; valid: {', '.join(dataset_names())}")
        if not isinstance(table, dict) or not {"identifier", "why"} <= set(table) <= {"identifier", "why", "beside"}:
            raise ConfigError(
                f"{path}: [{dname}] needs exactly `identifier` and a `why` line (and optionally "
                "`beside`, a list of identifiers)"
            )
        ident, why = table["identifier"], table["why"]
        if ident not in IDENTIFIERS:
            raise ConfigError(f"{path}: [{dname}] identifier {ident!r} unknown; valid: {', '.join(IDENTIFIERS)}")
        if not (isinstance(why, str) and why.strip()):
            raise ConfigError(f"{path}: [{dname}] needs a `why` line saying which measurement chose {ident!r}")
        beside = table.get("beside", [])
        if not (isinstance(beside, list) and all(isinstance(b, str) for b in beside)):
            raise ConfigError(f"{path}: [{dname}] `beside` must be a list of identifiers")
        for b in beside:
            if b not in IDENTIFIERS:
                raise ConfigError(f"{path}: [{dname}] beside identifier {b!r} unknown; valid: {', '.join(IDENTIFIERS)}")
        if ident in beside or len(set(beside)) != len(beside):
            raise ConfigError(f"{path}: [{dname}] `beside` repeats an identifier or names the row's own {ident!r}")
        entries.append(Entry(dname, ident, why.strip(), tuple(beside)))
    return entries


def beside_entries(entries: Sequence[Entry]) -> list[Entry]:
    """One entry per identifier shown beside a chosen row, in the settings' order."""
    return [
        Entry(e.dataset, b, f"shown beside `{e.identifier}` for comparison", beside_of=e.identifier)
        for e in entries
        for b in e.beside
    ]


def with_beside(entries: Sequence[Entry]) -> list[Entry]:
    """Every row of ``entries``: each chosen row followed by those shown beside it (the table's order)."""
    return [x for e in entries for x in (e, *beside_entries([e]))]


def seeds_text(seeds: Sequence[int]) -> str:
    """``A-B`` for consecutive seeds (the form ``score --seeds`` takes)."""
    seeds = [int(s) for s in seeds]
    if not seeds or seeds != list(range(seeds[0], seeds[0] + len(seeds))):
        raise ConfigError(f"records need consecutive training seeds (A-B), got {seeds}")
    return f"{seeds[0]}-{seeds[-1]}"


def measure_command(entry: Entry) -> str:
    """The ``piezotwin records`` command that measures one row again."""
    return f"piezotwin records --datasets {entry.dataset}" + (
        f" --identifiers {entry.identifier}" if entry.beside_of else ""
    )


def command(dataset: str, identifier: str, seeds: Sequence[int] = DEFAULT_SEEDS) -> str:
    """The ``piezotwin score`` command that reproduces one row with the default (full) settings."""
    return f"piezotwin score --datasets {dataset} --identifiers {identifier} --seeds {seeds_text(seeds)} --json"


def provenance() -> dict[str, Any]:
    """What a measured time depends on: date, machine (CPU, cores, torch kernels), load and package versions."""
    from importlib.metadata import PackageNotFoundError, version

    from benchmarks.scoring.core import environment

    env = environment()
    versions = env.pop("versions", {})
    for dist in ("piezotwin", "sysidentpy"):
        try:
            versions[dist] = version(dist)
        except PackageNotFoundError:
            versions[dist] = None
    return {
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": {**env, "cores": os.cpu_count()},
        "versions": versions,
    }


def measure(
    entry: Entry, seeds: Sequence[int] = DEFAULT_SEEDS, executor=None, progress: bool = False, fresh: bool = True
) -> dict[str, Any]:
    """Score one row as its :func:`command` does and return it with how it was measured (not yet stored).

    Without a Dask ``executor`` the row is measured in a new Python process (``fresh``), as the printed command
    runs: its times then include what a user's first fit pays (numba compilation) and nothing of the rows
    measured before it; ``fresh=False`` measures here (quicker to start, times depend on what ran before).
    With a Dask executor the fits run on its workers and ``cpu_seconds`` counts none of them."""
    if not fresh or getattr(executor, "client", None) is not None:
        return _measure(entry, [int(s) for s in seeds], executor, progress)
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(_measure, entry, [int(s) for s in seeds], None, progress, "fresh").result()


def _measure(entry: Entry, seeds: list[int], executor, progress: bool, process: str | None = None) -> dict[str, Any]:
    """The row measured where this runs; ``process`` says where that is (fresh, in-process, dask workers)."""
    from benchmarks import scoring

    if process is None:
        process = "in-process" if getattr(executor, "client", None) is None else "dask workers"

    load_before = list(os.getloadavg())
    wall0, cpu0 = time.perf_counter(), time.process_time()
    run = scoring.score(
        [entry.identifier], [entry.dataset], quick=False, progress=progress, seeds=seeds, executor=executor
    )
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    measured = provenance()
    measured.update(
        load_average_before=load_before,
        load_average_after=list(os.getloadavg()),
        wall_seconds=wall,
        cpu_seconds=cpu,
        process=process,
    )
    return {
        "format": ROW_FORMAT,
        "dataset": entry.dataset,
        "identifier": entry.identifier,
        "seeds": seeds,
        "command": command(entry.dataset, entry.identifier, seeds),
        "why": entry.why,
        "measured": measured,
        "score": scoring._clean(run.to_dict()),
    }


def row_path(directory: str | Path, dataset: str, identifier: str | None = None) -> Path:
    """``<dataset>.json`` for a chosen row, ``<dataset>--<identifier>.json`` for a row shown beside it."""
    return Path(directory) / f"{row_key(dataset, identifier)}.json"


def write_row(row: dict[str, Any], directory: str | Path, beside: bool = False) -> Path:
    """Store one measured row as ``<directory>/<dataset>.json`` (``beside``: ``<dataset>--<identifier>.json``),
    atomically."""
    from sysid.data.jsonio import clean_json
    from sysid.data.safeio import atomic_write_text

    path = row_path(directory, row["dataset"], row["identifier"] if beside else None)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(clean_json(row), indent=1, ensure_ascii=False) + "\n")
    return path


def load_rows(entries: Sequence[Entry], directory: str | Path) -> tuple[dict[str, dict[str, Any]], list[Entry]]:
    """The stored rows of ``entries`` and of the rows shown beside them (by :attr:`Entry.key`: the dataset, or
    ``dataset--identifier``) and the entries that have none yet. A stored row of another identifier than the
    entry names counts as missing (the settings changed since it was measured)."""
    rows, missing = {}, []
    for e in with_beside(entries):
        path = Path(directory) / f"{e.key}.json"
        if not path.exists():
            missing.append(e)
            continue
        row = _read_row(path)
        if row["dataset"] != e.dataset:
            raise ConfigError(f"{path}: holds the row of {row['dataset']!r}, not of {e.dataset!r}")
        if row["identifier"] != e.identifier:
            missing.append(e)
            continue
        rows[e.key] = row
    return rows, missing


def _read_row(path: Path) -> dict[str, Any]:
    try:
        row = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read a stored records row ({exc})") from None
    if not (
        isinstance(row, dict)
        and row.get("format") == ROW_FORMAT
        and isinstance(row.get("score"), dict)
        and isinstance(row["score"].get("rows"), list)
        and isinstance(row.get("measured"), dict)
        and all(isinstance(row.get(k), str) for k in ("dataset", "identifier", "command"))
    ):
        raise ConfigError(
            f"{path}: not a stored records row (format {ROW_FORMAT!r} with dataset, identifier, "
            "command, measured and score)"
        )
    return row


def score_rows(row: dict[str, Any]) -> list[dict[str, Any]]:
    """The scored test rows of one stored row (its identifier on its dataset), in test order."""
    return [
        r
        for r in row["score"]["rows"]
        if r.get("identifier") == row["identifier"] and r.get("dataset") == row["dataset"]
    ]


def _test_rmse(r: dict[str, Any]) -> dict[str, Any]:
    """mean / sd / seeds of one scored test row (``seeds``: seed -> free-run RMSE, or ``"deterministic"``)."""
    if r.get("status") == "error":
        return {"mean": None, "sd": None, "seeds": None}
    seeds = r.get("seeds")
    if isinstance(seeds, list):
        by_seed = {str(s): v for s, v in zip(seeds, r.get("free_run_rmse_by_seed") or [])}
        return {"mean": r.get("free_run_rmse_mean"), "sd": r.get("free_run_rmse_sd"), "seeds": by_seed}
    rmse = (r.get("free_run") or {}).get("rmse")
    return {"mean": rmse, "sd": 0.0 if rmse is not None else None, "seeds": "deterministic"}


def _record(r: dict[str, Any]) -> dict[str, Any] | None:
    """The best published result on the row's test: from today's published results (a published figure is not part
    of the measurement, so a corrected or added one shows without refitting), with its source, else as the row
    stored it (without a source)."""
    from benchmarks import published
    from benchmarks.datasets.references import references_for

    dname, test = r.get("dataset", ""), r.get("test", "")
    best = references_for(dname).get(test, {}).get("best_published") or (r.get("references") or {}).get(
        "best_published"
    )
    if not best:
        return None
    out = {k: best[k] for k in ("value", "unit", "model")}
    shown = published.best_published(dname, test)
    if shown:
        out["source"] = shown["source"]
    return out


def summarise_row(row: dict[str, Any]) -> dict[str, Any]:
    """One dataset's entry of ``records.json``: identifier, free-run RMSE per test (mean, sd, seeds) and its unit,
    the mean training time of one model (seconds), the reproducing command, the published record per test, and
    when and on what machine the row was measured (``measured``: date, machine)."""
    tests = score_rows(row)
    fits = [r.get("fit_seconds_mean", r.get("fit_seconds")) for r in tests]
    fits = [f for f in fits if isinstance(f, (int, float))]
    meas = row["measured"]
    return {
        "identifier": row["identifier"],
        "rmse": {r["test"]: _test_rmse(r) for r in tests},
        "units": {r["test"]: r.get("units", "") for r in tests},
        "seconds": fits[0] if fits else None,
        "command": row["command"],
        "record": {r["test"]: _record(r) for r in tests},
        "measured": {"date": meas.get("date"), "machine": meas.get("machine")},
    }


def summary(entries: Sequence[Entry], rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """``records.json``: dataset -> :func:`summarise_row`, in the order of ``records.toml``; rows not stored yet
    are left out (:func:`load_rows` names them)."""
    return {e.dataset: summarise_row(rows[e.dataset]) for e in entries if e.dataset in rows}


def fmt_value(x: Any, unit: str = "") -> str:
    """A figure for the page: mV below 0.1 V, 3 significant digits; ``—`` when missing or not finite."""
    if not isinstance(x, (int, float)) or isinstance(x, bool) or not math.isfinite(x):
        return "—"
    if unit == "V" and abs(x) < 0.1:
        x, unit = x * 1e3, "mV"
    text = f"{x:#.3g}"  # 3 significant digits, trailing zeros kept (0.260)
    text = text.rstrip(".") if "e" not in text else text
    return f"{text} {unit}".strip()


def fmt_spread(rmse: dict[str, Any], unit: str) -> str:
    """``mean ± SD unit (seeds A-B)``, or ``value unit (deterministic)``, in the unit :func:`fmt_value` picks."""
    mean, sd = rmse.get("mean"), rmse.get("sd")
    text = fmt_value(mean, unit)
    if text == "—":
        return "diverged or failed" if rmse.get("seeds") is not None else "error"
    if rmse["seeds"] == "deterministic":
        return f"{text} (deterministic)"
    scale = 1e3 if text.endswith(" mV") else 1.0
    value, shown_unit = text.split(" ", 1) if " " in text else (text, "")
    seeds = [int(s) for s in rmse["seeds"]]
    n_bad = sum(v is None for v in rmse["seeds"].values())
    spread = f"{value} ± {sd * scale:.2g} {shown_unit}".strip() if isinstance(sd, (int, float)) else text
    bad = f", {n_bad} diverged" if n_bad else ""
    return f"{spread} (seeds {seeds[0]}-{seeds[-1]}{bad})"


def _settings_text(params: dict[str, Any]) -> str:
    """The options as ``--set`` writes them (a list with dashes: ``hidden=25-25``)."""

    def value(v: Any) -> str:
        return "-".join(str(x) for x in v) if isinstance(v, (list, tuple)) else str(v)

    return ", ".join(f"{k}={value(v)}" for k, v in params.items()) or "defaults"


def page_context(entries: Sequence[Entry], rows: dict[str, dict[str, Any]], missing: Sequence[Entry]) -> dict[str, Any]:
    """What the page template shows: one line per dataset and test, one per stored row's measurement, and the
    rows not measured yet with the command that measures them."""
    lines, measurements = [], []
    for e in with_beside(entries):
        if e.key not in rows:
            continue
        row = rows[e.key]
        entry = summarise_row(row)
        for r in score_rows(row):
            unit = r.get("units", "")
            rec = entry["record"][r["test"]]
            lines.append(
                {
                    "dataset": e.dataset,
                    "test": r["test"],
                    "identifier": row["identifier"],
                    "beside": bool(e.beside_of),
                    "settings": _settings_text(r.get("params") or {}),
                    "rmse": fmt_spread(entry["rmse"][r["test"]], unit),
                    "seconds": "—" if entry["seconds"] is None else f"{entry['seconds']:.3g}",
                    "record": _record_text(rec, unit),
                    "command": row["command"],
                }
            )
        m = row["measured"]
        versions = m.get("versions") or {}
        measurements.append(
            {
                "dataset": f"{e.dataset} (`{e.identifier}`, beside)" if e.beside_of else e.dataset,
                "date": m.get("date", "?"),
                "cpu": (m.get("machine") or {}).get("cpu", "?"),
                "cores": (m.get("machine") or {}).get("cores", "?"),
                "load": " → ".join(
                    f"{(m.get(k) or [math.nan])[0]:.1f}" for k in ("load_average_before", "load_average_after")
                ),
                "wall": f"{m.get('wall_seconds', math.nan):.1f}",
                "cpu_s": f"{m.get('cpu_seconds', math.nan):.1f}",
                "versions": ", ".join(f"{k} {v}" for k, v in versions.items() if v),
            }
        )
    return {
        "lines": lines,
        "published": _published_context(entries),
        "baselines": _baselines_context(),
        "measurements": measurements,
        "why": [(e.dataset, e.identifier, e.why) for e in entries],
        "missing": [{"dataset": e.dataset, "identifier": e.identifier, "command": measure_command(e)} for e in missing],
        "default_seeds": seeds_text(DEFAULT_SEEDS),
    }


def _record_text(rec: dict[str, Any] | None, unit: str) -> str:
    """The record cell: ``0.260 mV (PNLSS; Paduart et al. 2010 in Champneys et al. 2024)``."""
    if not rec:
        return "—"
    source = f"; {rec['source']}" if rec.get("source") else ""
    return f"{fmt_value(rec['value'], unit)} ({rec['model']}{source})"


def _published_context(entries: Sequence[Entry]) -> list[dict[str, str]]:
    """One line per test of the table's datasets that has a best published result: the number as the paper prints
    it, the model, the source in full and where this project read it."""
    from benchmarks import published
    from benchmarks.datasets.references import references_for

    out = []
    for e in entries:
        for test in references_for(e.dataset):
            best = published.best_published(e.dataset, test)
            if best:
                out.append(
                    {
                        "dataset": e.dataset,
                        "test": test,
                        "value": f"{best['value']:g} {best['unit']}",
                        "model": best["model"],
                        "cite": best["cite"],
                        "read_from": best["read_from"],
                    }
                )
    return out


def _baselines_context() -> dict[str, Any]:
    """The baselines table (:func:`benchmarks.published.baselines_text`), figures in the page's format."""
    from benchmarks import published
    from benchmarks.scoring.floors import load_baselines

    return published.baselines_text(fmt_value, load_baselines().get("modes", {}).get("full", {}))


def render_markdown(entries: Sequence[Entry], rows: dict[str, dict[str, Any]], missing: Sequence[Entry]) -> str:
    """The whole ``docs/benchmarks.md``: the page template with the records tables filled from stored rows."""
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(TEMPLATES_DIR),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        autoescape=False,
    )
    return env.get_template(TEMPLATE).render(**page_context(entries, rows, missing))


def write_outputs(
    entries: Sequence[Entry],
    rows: dict[str, dict[str, Any]],
    missing: Sequence[Entry],
    markdown: str | Path,
    records_json: str | Path,
) -> dict[str, Any]:
    """Render both outputs and write them atomically; returns the ``records.json`` mapping."""
    from sysid.data.jsonio import clean_json
    from sysid.data.safeio import atomic_write_text

    text = render_markdown(entries, rows, missing)
    data = clean_json(summary(entries, rows))
    atomic_write_text(records_json, json.dumps(data, indent=2, ensure_ascii=False) + "\n")
    atomic_write_text(markdown, text)
    return data
