"""Score reports: the markdown table and the report directory (score.json, score.md, figures)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.scoring.core import ScoreRun, _finite, _fmt
from sysid.data.jsonio import clean_json


def markdown_table(run: ScoreRun | dict[str, Any]) -> str:
    """The score table: one row per identifier × dataset × test, references and SysIdentPy beside it."""
    data = run.to_dict() if isinstance(run, ScoreRun) else run
    sidp = {(r["dataset"], r["test"]): r for r in data.get("sysidentpy", [])}
    lines = [
        "| dataset / test | identifier | free-run RMSE | free-run R² | one-step RMSE | fit s | params | "
        "SysIdentPy FROLS (same split) | linear baseline | best published | SysIdentPy published |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in data["rows"]:
        ref = r.get("references") or {}
        u = r.get("units", "")
        s = sidp.get((r["dataset"], r["test"]))
        if s is None:
            stxt = "—"
        elif s.get("status") == "ok":
            stxt = f"{_fmt(s['free_run']['rmse'])} ({s['n_parameters']} terms)"
        else:
            stxt = f"skipped: {s.get('reason', '')}"

        def refv(k: str) -> str:  # called only in this iteration: ref is this row's
            v = ref.get(k)  # noqa: B023
            return f"{_fmt(v['value'])} ({v['model']})" if v else "—"

        if r.get("status") == "error":
            lines.append(
                f"| {r['dataset']} / {r['test']} | {r['identifier']} | error | | | | | {stxt} | "
                f"{refv('linear_baseline')} | {refv('best_published')} | {refv('sysidentpy')} |"
            )
            continue
        fr, os_ = r["free_run"], r["one_step"]
        lines.append(
            f"| {r['dataset']} / {r['test']} | {r['identifier']} | {_fmt(fr['rmse'])} {u} | {_fmt(fr['r2'])} | "
            f"{_fmt(os_['rmse'])} | {r['fit_seconds']:.2f} | {r['n_parameters']} | {stxt} | "
            f"{refv('linear_baseline')} | {refv('best_published')} | {refv('sysidentpy')} |"
        )
    return "\n".join(lines) + "\n"


def write_report(run: ScoreRun, report_dir: str | Path) -> dict[str, Path]:
    """score.json, score.md and figures (free-run NRMSE bars; measured vs free-run for each dataset test), each
    written atomically (:mod:`sysid.data.safeio`)."""
    from sysid.data.safeio import atomic_write_text
    from sysid.report.plots import pyplot, save_and_close

    plt = pyplot()
    out = Path(report_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Path] = {}
    paths["json"] = out / "score.json"
    atomic_write_text(paths["json"], json.dumps(clean_json(run.to_dict()), indent=2))
    paths["markdown"] = out / "score.md"
    atomic_write_text(paths["markdown"], markdown_table(run))
    ok = [r for r in run.rows if r.get("status") in ("ok", "diverged")]
    if ok:
        labels = sorted({f"{r['dataset']}/{r['test']}" for r in ok})
        idents = sorted({r["identifier"] for r in ok})
        fig, ax = plt.subplots(figsize=(max(6, 0.9 * len(labels) + 2), 4))
        w = 0.8 / max(1, len(idents))
        for k, ident in enumerate(idents):
            vals = []
            for lab in labels:
                r = next((x for x in ok if x["identifier"] == ident and f"{x['dataset']}/{x['test']}" == lab), None)
                v = r["free_run"]["nrmse"] if r else None
                vals.append(v if _finite(v) else np.nan)
            ax.bar(np.arange(len(labels)) + k * w, vals, w, label=ident)
        ax.set_xticks(np.arange(len(labels)) + 0.4 - w / 2, labels, rotation=30, ha="right", fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel("free-run NRMSE (log)")
        ax.set_title("test accuracy, free-run simulation")
        ax.legend(fontsize=8)
        fig.tight_layout()
        paths["nrmse"] = out / "score_nrmse.png"
        save_and_close(fig, paths["nrmse"], dpi=90)
    # measured vs free-run predictions: one figure per dataset (first test), the whole scored record and a zoom
    if run.predictions and run.datasets:
        from sysid.report.plots import plot_measured_vs_predicted

        for dname, ds in run.datasets.items():
            test = next(iter(ds.tests))
            rec = ds.tests[test]
            keys = [k for k in run.predictions if k[1] == dname and k[2] == test]
            if not keys:
                continue
            n0 = ds.init_for(test)
            t = np.arange(n0, len(rec)) / rec.fs
            preds = {k[0]: np.asarray(run.predictions[k])[n0:] for k in sorted(keys)}
            p = plot_measured_vs_predicted(
                t,
                rec.y[n0:],
                preds,
                out / f"freerun_{dname}_{test}.png",
                title=f"{dname} / {test}: free-run simulation",
                unit=ds.units.get("y", ""),
            )
            paths[f"freerun_{dname}"] = p
    return paths
