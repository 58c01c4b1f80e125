"""The main job's scoring stages (:mod:`benchmarks.mainjob`): every identifier on the twin datasets and on the
recorded lab benchmarks at the budgets of the quick check, each row judged against the floor measured at the same
budget, and the long rows of the records table shown as stored, with the command that measures them again.

Budgets. The identifiers' default settings are the full ones of the records table (wh-net 1500 epochs, 335 s per
seed; ss-encoder 150 epochs, 842 s per seed): every identifier on every dataset with them takes hours on 2 cores.
The main job fits each pair with the quick settings (``[quick.*]`` tables of
``benchmarks/settings/identifiers/*.toml``, the sample budgets and dataset choices of ``settings/quick.toml``) and
trains each seeded identifier once (seed 0). The quick floors of ``benchmarks/baselines.json`` were measured at
those budgets; for a seeded pair the floor is at least the worst single seed of seeds 0-19 on every CPU kernel
set x 1.15 (:func:`benchmarks.scoring.make_floors`), so one seed is judged by a floor that covers it. A row with no
floor at these budgets (none of the runs that set the floors scored it) is shown and counted as not compared.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from benchmarks.mainjob_context import Context, StageSkipped
from sysid.report.html import esc, table

#: training seeds of the seeded identifiers in the main job: one draw, judged by floors that cover every single seed
MAIN_SEEDS = (0,)
#: ``--quick``: the datasets scored (the default run scores every twin and lab dataset that has quick floors)
QUICK_PLAN = {"twins": ("acoustic-thesis",), "lab": ("silverbox",)}


def plan(quick: bool) -> dict[str, list[str]]:
    """The datasets each scoring stage scores: those of the quick check (they have floors at its budgets), split
    into the twins' and the recorded lab benchmarks'; ``quick`` keeps one of each (:data:`QUICK_PLAN`)."""
    from benchmarks.datasets import lab
    from benchmarks.datasets import twin as twin_ds
    from benchmarks.scoring import QUICK_DATASETS

    out = {
        "twins": [d for d in QUICK_DATASETS if d in twin_ds.TWIN_DATASETS],
        "lab": [d for d in QUICK_DATASETS if d in lab.LAB_SPECS],
    }
    if quick:
        out = {k: [d for d in v if d in QUICK_PLAN[k]] for k, v in out.items()}
    return out


def _left_datasets(ctx: Context, scored: list[str], candidates: list[str]) -> None:
    """Name the datasets of ``candidates`` this run does not score, with the command that scores them."""
    from benchmarks.scoring import QUICK_DATASETS

    for d in candidates:
        if d in scored:
            continue
        why = (
            "no floor at the quick budgets (the regression check does not score it), so nothing to compare with"
            if d not in QUICK_DATASETS
            else "left out by --quick"
        )
        ctx.leave(f"identifiers on {d}", why, f"piezotwin score --quick --datasets {d}")


def _score_stage(ctx: Context, datasets: list[str], key: str, title: str, sysidentpy: bool) -> str:
    from benchmarks import scoring
    from sysid.registry import available_identifiers

    idents = available_identifiers()
    if not idents:
        raise StageSkipped("no identifier built yet")
    if not datasets:
        raise StageSkipped("no dataset available")
    # every available identifier, as the regression check selects them (it leaves out the identifiers of
    # QUICK_SKIP_IDENTIFIERS and the pairs outside QUICK_ONLY_DATASETS, listed under `skipped` with the reason)
    run = scoring.score(None, datasets, quick=True, sysidentpy=sysidentpy, progress=ctx.verbose, seeds=MAIN_SEEDS)
    idents = run.selection.get("identifiers", idents)
    ctx.data[key] = run
    sub = ctx.report_dir / key
    paths = scoring.write_report(run, sub)
    for p in paths.values():
        if p.suffix == ".png":
            ctx.figures.append((f"{title}: {p.stem.replace('_', ' ')}", f"{key}/{p.name}"))
    base = scoring.load_baselines()
    data = run.to_dict()
    loose = set(scoring.unfloored(data, base))
    judged = {**data, "rows": [r for r in data["rows"] if (r["identifier"], r["dataset"], r["test"]) not in loose]}
    failures = scoring.check(judged, base)
    ctx.data[f"{key}_check"] = failures
    ctx.data[f"{key}_compared"] = len(judged["rows"])
    ctx.data[f"{key}_not_compared"] = sorted(loose)
    chk = (
        f"<p>Compared with the quick floors of benchmarks/baselines.json, measured at the same budgets: "
        f"{len(judged['rows'])} rows, "
        + (
            "all met.</p>"
            if not failures
            else "these below their floor:</p><ul>" + "".join(f"<li>{esc(f)}</li>" for f in failures) + "</ul>"
        )
    )
    if loose:
        chk += (
            "<p>Not compared (no floor at these budgets): "
            + ", ".join(esc(f"{i} on {d}/{t}") for i, d, t in sorted(loose))
            + "</p>"
        )
    skipped = "".join(
        f"<li>{esc(' on '.join(x for x in (s.get('identifier'), s.get('dataset')) if x))}: {esc(s['reason'])}</li>"
        for s in run.skipped
    )
    budget = (
        f"<p>Budgets: the quick check's settings (<code>[quick.*]</code> tables), seeded identifiers trained "
        f"with seed {', '.join(map(str, MAIN_SEEDS))}; the full-budget records are in the table of stored rows "
        f"below.</p>"
    )
    ctx.section(
        title,
        budget
        + _html_score_table(run)
        + chk
        + (f"<p>Skipped:</p><ul>{skipped}</ul>" if skipped else "")
        + f"<p>JSON: <a href='{key}/score.json'>{key}/score.json</a>, "
        f"Markdown: <a href='{key}/score.md'>{key}/score.md</a></p>",
    )
    ok = [r for r in run.rows if r.get("status") == "ok"]
    best: dict[tuple[str, str], dict[str, Any]] = {}
    for r in ok:
        k2 = (r["dataset"], r["test"])
        if k2 not in best or r["free_run"]["nrmse"] < best[k2]["free_run"]["nrmse"]:
            best[k2] = r
    summary = ", ".join(f"{d}/{t}: {r['identifier']} NRMSE {r['free_run']['nrmse']:.3g}" for (d, t), r in best.items())
    loose_txt = f", {len(loose)} without a floor at this budget (not compared)" if loose else ""
    return (
        f"{len(run.rows)} rows ({len(idents)} identifiers x {len(datasets)} datasets, quick budgets, seed "
        f"{MAIN_SEEDS[0]}) in {run.seconds:.0f} s; {len(judged['rows'])} compared with quick floors, "
        f"{len(failures)} below floor{loose_txt}; best free run: {summary}"
    )


_SCORE_HEADER = [
    "dataset / test",
    "identifier",
    "free-run RMSE",
    "free-run R²",
    "one-step RMSE",
    "fit [s]",
    "params",
    "SysIdentPy FROLS",
    "linear baseline",
    "best published",
    "SysIdentPy published",
]


def _html_score_table(run) -> str:
    from benchmarks.scoring import _fmt

    sidp = {(r["dataset"], r["test"]): r for r in run.sysidentpy}

    def ref_cell(r: dict[str, Any], kind: str) -> str:
        v = (r.get("references") or {}).get(kind)
        return f"{_fmt(v['value'])} ({esc(v['model'])})" if v else ""

    rows = []
    for r in run.rows:
        s = sidp.get((r["dataset"], r["test"]))
        st = (
            ""
            if s is None
            else (_fmt(s["free_run"]["rmse"]) if s.get("status") == "ok" else f"skipped: {esc(s.get('reason', ''))}")
        )
        if r.get("status") == "error":
            cells = [
                f"{r['dataset']} / {r['test']}",
                r["identifier"],
                "error: " + esc(r.get("message", "")),
                "",
                "",
                "",
                "",
            ]
        else:
            cells = [
                f"{r['dataset']} / {r['test']}",
                r["identifier"],
                f"{_fmt(r['free_run']['rmse'])} {esc(r['units'])}",
                _fmt(r["free_run"]["r2"]),
                _fmt(r["one_step"]["rmse"]),
                f"{r['fit_seconds']:.2f}",
                str(r["n_parameters"]),
            ]
        rows.append(cells + [st] + [ref_cell(r, k) for k in ("linear_baseline", "best_published", "sysidentpy")])
    return table(_SCORE_HEADER, rows, cls="score")


def stage_identify_twins(ctx: Context) -> str:
    from benchmarks.datasets import twin as twin_ds

    wanted = plan(ctx.quick)["twins"]
    names = [n for n in wanted if n in ctx.data.get("twin_datasets", {})]
    _left_datasets(ctx, names, list(twin_ds.TWIN_DATASETS))
    if not names:
        raise StageSkipped("no twin dataset available")
    msg = _score_stage(ctx, names, "twins", "Identifiers on the twin datasets", sysidentpy=False)
    _residual_figure(ctx)
    return msg


def _residual_figure(ctx: Context) -> None:
    """Residual correlation tests (eq. 2-32, Figure 5.6 analogue) of the best one-step model on a twin test."""
    try:
        from sysid.evaluation.residuals import correlation_tests
    except ImportError:
        return
    run = ctx.data.get("twins")
    if run is None:
        return
    ok = [r for r in run.rows if r.get("status") == "ok" and np.isfinite(r["one_step"]["rmse"] or np.nan)]
    if not ok:
        return
    r = min(ok, key=lambda x: x["one_step"]["nrmse"])
    from benchmarks import scoring
    from sysid.registry import get_identifier
    from sysid.report.plots import draw_correlation_test, pyplot

    ds = run.datasets[r["dataset"]]
    # residual tests on the estimation record (as the dissertation's Figure 5.6), first 20 000 samples
    rec = ds.est_records[0]
    rec = rec[: min(len(rec), 20000)]
    cls_params = dict(r["params"])
    norm = bool(cls_params.pop(scoring.NORMALISE, False))
    model = get_identifier(r["identifier"])(**cls_params)
    if norm:
        model = scoring.Normalised(model)
    model.fit(ds.est)
    yhat = model.predict(rec, horizon=1)
    skip = max(ds.init_samples, int(getattr(model, "max_lag_", 0)))
    e = rec.y[skip:] - yhat[skip:]
    res = correlation_tests(e, rec.u[skip:], max_lag=20)
    fig, axes = pyplot().subplots(1, len(res["tests"]), figsize=(13, 2.8))
    for ax, t in zip(np.atleast_1d(axes), res["tests"]):
        draw_correlation_test(ax, t)  # y-axis scaled to the data, band shaded
    fig.suptitle(
        f"residual tests (95 % band): {r['identifier']} one-step residuals on the {r['dataset']} estimation data",
        fontsize=10,
    )
    fig.tight_layout()
    ctx.save_figure(
        fig,
        "residual_tests",
        f"Residual correlation tests (eq. 2-32): {r['identifier']} on the {r['dataset']} estimation data",
    )


def stage_lab(ctx: Context) -> str:
    from benchmarks.datasets import lab

    names = plan(ctx.quick)["lab"]
    _left_datasets(ctx, names, list(lab.LAB_SPECS))
    msg = _score_stage(ctx, names, "lab", "Identifiers on recorded lab benchmarks", sysidentpy=True)
    n = stored_records(ctx)
    return msg + f"; {n} records-table rows shown as stored (benchmarks/records.json)"


def _machine_text(machine: dict[str, Any] | None) -> str:
    if not machine:
        return "machine not stored"
    parts = [machine.get("cpu") or machine.get("machine") or "?"]
    if machine.get("cores"):
        parts.append(f"{machine['cores']} cores")
    if machine.get("torch_cpu_capability"):
        parts.append(f"torch {machine['torch_cpu_capability']} kernels")
    return ", ".join(parts)


def stored_records(ctx: Context) -> int:
    """The records table's rows (full budgets, seeds 0-2) as stored in ``benchmarks/records.json``, marked as
    such, with when and where they were measured and the command that measures them again; each is named in
    the report's header as left to ``piezotwin records``. Returns how many rows it showed."""
    from benchmarks.records import RECORDS_JSON, fmt_spread, fmt_value
    from benchmarks.scoring import _fmt

    try:
        stored = json.loads(RECORDS_JSON.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        ctx.section("Records table (stored)", f"<p>benchmarks/records.json cannot be read: {esc(exc)}</p>")
        return 0
    rows = []
    for dname, e in stored.items():
        meas = e.get("measured") or {}
        when = meas.get("date", "date not stored")
        where = _machine_text(meas.get("machine"))
        secs = e.get("seconds")
        cost = f"{secs:.0f} s per model" if isinstance(secs, (int, float)) else "time not stored"
        for test, rm in (e.get("rmse") or {}).items():
            rec = (e.get("record") or {}).get(test) or {}
            unit = (e.get("units") or {}).get(test) or rec.get("unit", "")
            src = f"; {rec['source']}" if rec.get("source") else ""
            pub = (
                f"{fmt_value(rec.get('value'), rec.get('unit', unit))} ({esc(rec.get('model', '') + src)})"
                if rec
                else "—"
            )
            value = fmt_spread(rm, unit) if isinstance(rm, dict) else _fmt(rm)
            rows.append(
                [
                    esc(f"{dname} / {test}"),
                    esc(e.get("identifier", "")),
                    esc(value),
                    pub,
                    esc(when),
                    esc(where),
                    esc(cost),
                    f"<code>{esc(e.get('command', ''))}</code>",
                ]
            )
        ctx.leave(
            f"records table: {e.get('identifier')} on {dname} at full budget, seeds 0-2",
            f"{cost}; stored {when} on {where}",
            f"piezotwin records --datasets {dname}",
        )
    ctx.section(
        "Records table (stored, not recomputed by this run)",
        "<p>The long rows of the records table: full budgets, training seeds 0-2, read from "
        "<code>benchmarks/records.json</code> as stored on the date and machine shown. This run did not "
        "recompute them; <code>piezotwin records</code> does (the command of each row reproduces it).</p>"
        + table(
            [
                "dataset / test",
                "identifier",
                "free-run RMSE (stored)",
                "best published",
                "measured on",
                "machine",
                "training time",
                "command",
            ],
            rows,
            cls="score",
        ),
    )
    return len(stored)
