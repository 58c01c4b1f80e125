"""Running benchmark cases: one row per case, written as it finishes, so that an interrupted run resumes.

:func:`run_case` builds a case's records (:mod:`.truth`), diagnoses them with the defaults a user gets
(:func:`twins.discrepancy.diagnose`, three rounds) and returns one JSON row: the case, the mechanism's
parameters and realised size, the verdict, the named causes (effect, confidence, group, parameters, p-value),
the validation NRMSE before and after, the fitted parameters that ended on a bound of their range
(``at_bound``), the CPU and wall seconds of the diagnosis and the code's git commit
(``code``). A case that cannot be
built or diagnosed is a row with ``error`` (the benchmark counts it, nothing is dropped). :func:`run_cases`
runs many on the project's execution backend (:mod:`benchmarks.execution`: in-process, ``--workers N`` or a
Dask scheduler), appending each row to a JSON-lines file; cases already in the file are not run again.
"""

from __future__ import annotations

import json
import os
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from .cases import Case, draw_case

__all__ = ["run_case", "run_cases", "read_rows", "ROW_FORMAT"]

ROW_FORMAT = "piezotwin-diagnosis-bench/1"
#: the diagnosis's settings in the benchmark: its defaults (a user's first run)
MAX_ROUNDS = 3


#: what the benchmark keeps of a named cause: enough to score it and to refit its confidence
CAUSE_KEYS = (
    "effect",
    "confidence",
    "score",
    "group",
    "params",
    "p_value",
    "kind",
    "round",
    "family",
    "nrmse_val_before",
    "nrmse_val_after",
    "joint_with",
    "joint_with_named",
    "replaces",
    "above_nyquist",
    "pinned_frequency",
    "beyond_record",
    "untransferable",
)


def _cause(c: dict[str, Any]) -> dict[str, Any]:
    out = {k: c[k] for k in CAUSE_KEYS if k in c}
    out["confidence"] = float(c.get("confidence", 0.0))
    out["group"] = list(c.get("group", []))
    return out


def run_case(seed: int) -> dict[str, Any]:
    """Build and diagnose the case of ``seed``; one JSON row (module docstring)."""
    from sysid.report.provenance import commit
    from twins.discrepancy import diagnose

    case = draw_case(seed)
    row: dict[str, Any] = {"format": ROW_FORMAT, "case": case.to_dict(), "code": commit()}
    try:
        built = _build(case)
        row.update(params=_plain(built["params"]), size_est=built["size_est"], size_val=built["size_val"])
        c0, w0 = time.process_time(), time.perf_counter()
        out = diagnose(built["twin"], built["est"], built["val"], max_rounds=MAX_ROUNDS, threads=1)
        row["cpu_s"], row["wall_s"] = time.process_time() - c0, time.perf_counter() - w0
    except Exception as exc:  # noqa: BLE001 — a case that fails is a result of the benchmark, with its reason
        row["error"] = f"{type(exc).__name__}: {exc}"
        row["traceback"] = traceback.format_exc(limit=6)
        return row
    row["verdict"] = out["verdict"]
    row["causes"] = [_cause(c) for c in out["causes"]]
    row["nrmse_val"] = {"before": out["baseline"]["nrmse_val"], "after": out["extended"]["nrmse_val"]}
    row["residual_vs_noise"] = out.get("residual_vs_noise", {}).get("excess_ratio")
    row["ranges"] = out.get("ranges", [])
    row["at_bound"] = _plain(out.get("at_bound", []))  # parameters on a range's bound: a mimic's mark
    return row


def _build(case: Case) -> dict[str, Any]:
    from .truth import make_records

    return make_records(case)


def _plain(obj: Any) -> Any:
    """JSON-able copy of a parameter dict or a list of them (numpy scalars to floats)."""
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if hasattr(obj, "item"):
        return obj.item()
    return obj


def read_rows(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The rows of a results file (a torn last line, from an interrupted write, is left out)."""
    p = Path(path)
    if not p.exists():
        return []
    rows = []
    for line in p.read_text(encoding="utf-8").splitlines():
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError:
            continue
    return rows


def run_cases(
    seeds: Sequence[int],
    path: str | os.PathLike,
    executor: Any | None = None,
    on_row: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Run the cases of ``seeds`` not yet in ``path`` and append a row per case as it finishes; every row of the
    requested seeds (old and new), in seed order. Each row is one ``write`` of one line, flushed and synced, so an
    interruption loses at most the case in flight."""
    from benchmarks.execution import make_executor

    done = {r["case"]["seed"]: r for r in read_rows(path) if r.get("format") == ROW_FORMAT}
    todo = [s for s in seeds if s not in done]
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", encoding="utf-8") as fh:

        def keep(_i: int, row: dict[str, Any]) -> None:
            fh.write(json.dumps(row, sort_keys=True) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
            done[row["case"]["seed"]] = row
            if on_row is not None:
                on_row(row)

        ex = executor if executor is not None else make_executor()
        try:
            ex.map(run_case, [(s,) for s in todo], desc="diagnosis cases", on_result=keep, keep=False)
        finally:
            if executor is None:
                ex.close()
    return [done[s] for s in seeds if s in done]
