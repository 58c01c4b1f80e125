"""Which fits each row needs, running them (here or on Dask workers) and turning the results into rows.

A row id names one published figure (:data:`benchmarks.thesis.targets.TARGETS`). :func:`tasks_for` lists the
fits behind the chosen rows — shared fits once (Table 4.3 reads the 4 × 25 runs of Table 4.2; Tables 5.5/5.6 and
Figure 5.13 read the runs of Table 5.4's networks) — and :func:`measure` runs them with an
:class:`benchmarks.execution.Executor` and builds the rows (:mod:`benchmarks.thesis.rows`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from typing import Any

from benchmarks.thesis import acoustic, cantilever, targets
from benchmarks.thesis.plan import Tier
from benchmarks.thesis.rows import build_row
from sysid.errors import ConfigError

__all__ = [
    "ROW_IDS",
    "select_rows",
    "tasks_for",
    "preset_tasks_for",
    "measure",
    "PRESET_FAMILIES",
    "PRESET_PREFIX",
    "measure_grid",
]

ROW_IDS: list[str] = list(targets.TARGETS)
_ARCH = targets.ARCH
BEST_DS2 = targets.BEST_DS2
#: the best line of each model class in Table 5.2 (its last NARX, ARMAX and NARMAX rows)
DS1_DELAYED = [[x for x in targets.TABLE_5_2 if x[0] == m][-1] for m in ("narx", "armax", "narmax")]


def select_rows(spec: str | None) -> list[str]:
    """Row ids from ``--rows``: ids or prefixes (``table-4.2`` = its nine rows); unknown ones are refused."""
    if not spec:
        return list(ROW_IDS)
    chosen: list[str] = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        hits = [r for r in ROW_IDS if r == item or r.startswith(item.rstrip("/") + "/")]
        if not hits:
            raise ConfigError(
                f"--rows: {item!r} is not a row id or table; valid tables: "
                f"{', '.join(sorted({r.split('/')[0] for r in ROW_IDS}))} (ids: table-4.2/4x25, ...)"
            )
        chosen += [h for h in hits if h not in chosen]
    return [r for r in ROW_IDS if r in chosen]


Task = tuple[Callable[..., dict[str, Any]], tuple]


def _family(rid: str) -> str:
    return rid.split("/")[0]


def tasks_for(row_ids: Sequence[str], t: Tier) -> dict[str, Task]:
    """key -> (function, arguments) of every fit the rows need (each key once)."""
    tasks: dict[str, Task] = {}
    fams = {_family(r) for r in row_ids}
    for rid in row_ids:
        fam, name = rid.split("/", 1)
        if fam in ("table-4.2", "table-4.3"):
            layers, width = (4, 25) if fam == "table-4.3" else tuple(int(x) for x in name.split("x"))
            for s in range(t.cantilever_repeats):
                tasks[f"cant/{layers}x{width}/{s}"] = (cantilever.mlp_task, (layers, width, s, t))
        elif fam == "table-5.2":
            line = next(x for x in targets.TABLE_5_2 if targets.table_5_2_id(*x[:5]) == rid)
            reps = t.narx_repeats if line[0] == "narx" else 1  # ARMAX and NARMAX fits are deterministic
            for s in range(reps):
                tasks[f"ds1/{name}/{s}"] = (acoustic.ds1_task, (*line[:5], s, t))
        elif fam in ("table-5.4", "table-5.5"):
            ny, hidden, act = _ARCH[name]
            for s in range(t.acoustic_repeats):
                tasks[f"ds2/{name}/{s}"] = (acoustic.ds2_task, (ny, hidden, act, s, t))
        elif fam in ("table-5.6", "fig-5.13"):
            ny, hidden, act = _ARCH[BEST_DS2]
            runs = t.table_5_6_runs if fam == "table-5.6" else t.fig_5_13_runs
            for s in range(runs):
                tasks[f"ds2/{BEST_DS2}/{s}"] = (acoustic.ds2_task, (ny, hidden, act, s, t))
        elif fam == "fig-3.4":
            tasks["cant/peak"] = (cantilever.output_peak_task, (t,))
        elif fam == "fig-3.9":
            tasks["vna/peaks"] = (acoustic.vna_peaks_task, (t,))
    # the project's other models on the same protocols (the "best model" column and the measured explanations)
    if fams & {"table-4.2", "table-4.3"}:
        for ident in cantilever.CANDIDATES:
            for s in range(1 if ident == "narx-poly" else t.cantilever_repeats):
                tasks[f"cant-cand/{ident}/{s}"] = (cantilever.candidate_task, (ident, s, t))
    if "table-4.3" in fams:
        for s in range(t.cantilever_repeats):
            tasks[f"cant-without/{cantilever.WITHOUT_FOR_4_3}/{s}"] = (
                cantilever.mlp_task,
                (4, 25, s, t, cantilever.WITHOUT_FOR_4_3),
            )
            for alpha in cantilever.ALPHA_TRIALS_FOR_4_3:
                tasks[f"cant-alpha/{alpha:g}/{s}"] = (cantilever.mlp_task, (4, 25, s, t, None, alpha))
    if "table-5.2" in fams:
        for nk in ("1", "tof"):
            tasks[f"ds1-cand/arx-nk{nk}"] = (acoustic.ds1_candidate_task, (nk, t))
        for line in DS1_DELAYED:  # each class's best line of the table with the input delayed past the dead time
            name = targets.table_5_2_id(*line[:5]).split("/", 1)[1]
            for s in range(t.narx_repeats if line[0] == "narx" else 1):
                tasks[f"ds1-cand/{name}-nktof/{s}"] = (acoustic.ds1_task, (*line[:5], s, t, "tof"))
        # the wavelet network of Table 5.1 on every NARX line's lags (and the best line's with the delay)
        for line in targets.TABLE_5_2:
            if line[0] == "narx":
                tasks[f"ds1-cand/wavenet-{line[1]}-{line[2]}/0"] = (acoustic.ds1_wavenet_task, (line[1], line[2], t))
        tasks[f"ds1-cand/wavenet-{DS1_DELAYED[0][1]}-{DS1_DELAYED[0][2]}-nktof/0"] = (
            acoustic.ds1_wavenet_task,
            (DS1_DELAYED[0][1], DS1_DELAYED[0][2], t, "tof"),
        )
        # what each class's failure depends on: the NARX at a smaller RMSprop step, the NARMAX at a smaller rho_p
        narx, narmax = DS1_DELAYED[0], DS1_DELAYED[2]
        name = targets.table_5_2_id(*narx[:5]).split("/", 1)[1]
        for nk in ("1", "tof"):
            for s in range(t.narx_repeats):
                tasks[f"ds1-cand/{name}-lr{acoustic.NARX_LR_SMALL:g}{'-nktof' if nk == 'tof' else ''}/{s}"] = (
                    acoustic.ds1_task,
                    (*narx[:5], s, t, nk, acoustic.NARX_LR_SMALL),
                )
        m, nu, ny, ne, _ = narmax[:5]
        name = targets.table_5_2_id(m, nu, ny, ne, acoustic.NARMAX_RHO_SMALL).split("/", 1)[1]
        tasks[f"ds1-cand/{name}-nktof/0"] = (acoustic.ds1_task, (m, nu, ny, ne, acoustic.NARMAX_RHO_SMALL, 0, t, "tof"))
    if fams & {"table-5.4", "table-5.5", "table-5.6", "fig-5.13"}:
        ny, hidden, act = _ARCH[BEST_DS2]
        for s in range(t.acoustic_repeats):
            tasks[f"ds2-cand/nk{acoustic.DS2_CANDIDATE_NK}/{s}"] = (
                acoustic.ds2_task,
                (ny, hidden, act, s, t, acoustic.DS2_CANDIDATE_NK),
            )
            tasks[f"ds2-dist/{acoustic.DS2_DISTANCE_TRIAL_M:g}/{s}"] = (
                acoustic.ds2_task,
                (ny, hidden, act, s, t, 1, acoustic.DS2_DISTANCE_TRIAL_M),
            )
    tasks.update(preset_tasks_for(row_ids, t))
    return tasks


#: the rows measured a second time on the thesis preset (:mod:`benchmarks.thesis.preset`), and their keys' prefix
PRESET_FAMILIES = ("fig-3.4", "table-5.2", "table-5.4", "table-5.5", "table-5.6", "fig-5.13")
PRESET_PREFIX = "preset/"


def preset_tasks_for(row_ids: Sequence[str], t: Tier) -> dict[str, Task]:
    """The fits of the rows of :data:`PRESET_FAMILIES` on the thesis preset (keys ``preset/<key>``): each row's own
    fits and, for Table 5.2's NARX lines, the smaller RMSprop step and the wavelet network beside them."""
    tasks: dict[str, Task] = {}
    for rid in row_ids:
        fam, name = rid.split("/", 1)
        if fam not in PRESET_FAMILIES:
            continue
        if fam == "table-5.2":
            line = next(x for x in targets.TABLE_5_2 if targets.table_5_2_id(*x[:5]) == rid)
            for s in range(t.narx_repeats if line[0] == "narx" else 1):
                tasks[f"ds1/{name}/{s}"] = (acoustic.ds1_task, (*line[:5], s, t, "1", None, True))
            if line[0] == "narx":
                tasks[f"ds1-cand/wavenet-{line[1]}-{line[2]}/0"] = (
                    acoustic.ds1_wavenet_task,
                    (line[1], line[2], t, "1", True),
                )
                for s in range(t.narx_repeats):
                    tasks[f"ds1-cand/{name}-lr{acoustic.NARX_LR_SMALL:g}/{s}"] = (
                        acoustic.ds1_task,
                        (*line[:5], s, t, "1", acoustic.NARX_LR_SMALL, True),
                    )
        elif fam in ("table-5.4", "table-5.5", "table-5.6", "fig-5.13"):
            arch = name if fam in ("table-5.4", "table-5.5") else BEST_DS2
            ny, hidden, act = _ARCH[arch]
            if fam in ("table-5.4", "table-5.5"):
                runs = t.acoustic_repeats
            else:
                runs = t.table_5_6_runs if fam == "table-5.6" else t.fig_5_13_runs
            for s in range(runs):
                tasks[f"ds2/{arch}/{s}"] = (acoustic.ds2_task, (ny, hidden, act, s, t, 1, None, True))
        elif fam == "fig-3.4":
            tasks["cant/peak"] = (cantilever.output_peak_task, (t, True))
    return {PRESET_PREFIX + k: v for k, v in tasks.items()}


def _cost(key: str) -> float:
    """Rough relative cost, to start the long fits first on a cluster."""
    key = key.removeprefix(PRESET_PREFIX)
    if key.startswith("cant/") and "x" in key:
        layers, width = key.split("/")[1].split("x")
        return float(layers) * float(width) ** 2
    return 1e4 if key.startswith("ds2") else 1.0


def measure(
    row_ids: Sequence[str],
    t: Tier,
    executor=None,
    progress: bool = False,
    on_task: Callable[[str, dict[str, Any]], None] | None = None,
) -> dict[str, dict[str, Any]]:
    """Run the fits of ``row_ids`` at tier ``t`` and return the rows (id -> row), each with how it was measured."""
    tasks = tasks_for(row_ids, t)
    by_key, measured = _run_tasks(tasks, {k: _cost(k) for k in tasks}, "thesis fits", executor, progress, on_task)
    measured.update(tier=t.as_dict())
    return {rid: build_row(rid, by_key, t, measured) for rid in row_ids}


def measure_grid(
    n: int | None,
    seed: int = 0,
    executor=None,
    progress: bool = False,
    on_task: Callable[[str, dict[str, Any]], None] | None = None,
) -> dict[str, Any]:
    """Table 5.3's grid: ``n`` configurations drawn with ``seed`` (``None``: all), each trained as §5.2 did, on the
    thesis preset's data set 2 (:mod:`benchmarks.thesis.grid`); the stored summary."""
    from benchmarks.thesis import grid

    configs = grid.sample(n, seed)
    tasks = grid.grid_tasks(configs)

    def cost(k: str) -> float:
        a = tasks[k][1]
        return float(a[8] + a[0]) * float(sum(a[1])) * float(max(a[1]))

    by_key, measured = _run_tasks(tasks, {k: cost(k) for k in tasks}, "Table 5.3 sample", executor, progress, on_task)
    return grid.summarize(configs, by_key, seed, measured)


def _run_tasks(
    tasks: dict[str, tuple],
    priorities: dict[str, float],
    desc: str,
    executor,
    progress: bool,
    on_task: Callable[[str, dict[str, Any]], None] | None,
) -> tuple[dict[str, dict[str, Any]], dict[str, Any]]:
    """Run ``tasks`` (key -> (function, args)) on the executor, costliest first; their results by key and how they
    were measured (provenance, load before and after, wall and CPU seconds here, the process)."""
    from benchmarks.execution import Executor
    from benchmarks.records import provenance

    ex = executor or Executor()
    keys = list(tasks)
    load0 = list(os.getloadavg())
    w0, c0 = time.perf_counter(), time.process_time()

    def report(i: int, res: dict[str, Any]) -> None:
        if on_task is not None:
            on_task(keys[i], res)

    results = ex.map(
        _run,
        [(tasks[k][0], tasks[k][1]) for k in keys],
        desc=desc,
        progress=progress,
        on_result=report,
        priorities=[priorities[k] for k in keys],
    )
    measured = provenance()
    measured.update(
        load_average_before=load0,
        load_average_after=list(os.getloadavg()),
        wall_seconds=time.perf_counter() - w0,
        cpu_seconds_here=time.process_time() - c0,
        process="in-process" if getattr(ex, "client", None) is None else f"dask ({ex.n_workers} workers)",
    )
    return dict(zip(keys, results)), measured


def _run(fn: Callable[..., dict[str, Any]], args: tuple) -> dict[str, Any]:
    return fn(*args)
