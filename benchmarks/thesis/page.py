"""``docs/dissertation.md`` rendered from the stored rows alone (no fitting), the Figure 5.13 histogram beside it,
and the cost of the full tier from the stored per-fit CPU times.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.thesis import grid as grid_5_3
from benchmarks.thesis import targets
from benchmarks.thesis.plan import TIERS

__all__ = ["render", "full_tier_cost", "write_histogram", "GRID_5_3"]

_TITLES = OrderedDict(
    [
        ("fig-3.4", "Figure 3.4 — cantilever output spectrum"),
        ("table-4.2", "Table 4.2 — nine MLP architectures, cantilever (mean validation FRS R² over 12 sines)"),
        ("table-4.3", "Table 4.3 — the 4 × 25 network, validation FRS R² per sine"),
        ("fig-3.9", "Figure 3.9 — acoustic transmission peaks"),
        ("table-5.2", "Table 5.2 — ARMAX, NARX and NARMAX on data set 1 (FRS R² on the estimation data)"),
        ("table-5.4", "Table 5.4 — eight networks on data set 2, estimation FRS R²"),
        ("table-5.5", "Table 5.5 — the same networks, validation FRS R² (1 ms chirp)"),
        ("table-5.6", "Table 5.6 — the 75-75 sigmoid network, five runs"),
        ("fig-5.13", "Figure 5.13 — the 75-75 sigmoid network over many runs"),
    ]
)
#: Table 5.3's grid, one width for every layer: lag values (n_u and n_y each), layers, widths, activations
GRID_5_3 = {
    "lags": len(grid_5_3.LAGS),
    "layers": len(grid_5_3.LAYERS),
    "widths": len(grid_5_3.WIDTHS),
    "activations": len(grid_5_3.ACTIVATIONS),
    "runs": grid_5_3.RUNS,
}
_EPOCH_FIELD = {
    "cant/": "cantilever_epochs",
    "cant-cand/narx-mlp": "cantilever_epochs",
    "cant-without/": "cantilever_epochs",
    "ds2": "acoustic_epochs",
    "ds1/narx": "narx_epochs",
    "ds1-cand/narx": "narx_epochs",
}


def _num(x: Any, unit: str = "", digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    if unit == "Hz":
        return f"{x / 1e3:.1f} kHz" if x >= 1e4 else f"{x:.0f} Hz"
    return f"{x:.{digits}f}" if abs(x) < 10 else f"{x:.3g}"  # a diverged free run's R² (−5.98e+04)


def _dissertation(d: dict[str, Any]) -> str:
    text = _num(d["value"], d["unit"])
    if d.get("sd") is not None and "runs" not in d:
        text += f" ± {_num(d['sd'], d['unit'])}"
    if d.get("runs"):
        text += f" (runs {_num(d['low'], d['unit'])}–{_num(d['high'], d['unit'])})"
    if d.get("n"):
        text += f", n = {d['n']}"
    return text


def _project(p: dict[str, Any]) -> str:
    if p["mean"] is None:
        return f"failed ({p['failed']} of {p['n']})"
    text = _num(p["mean"], p["unit"])
    if p.get("sd") is not None:
        text += f" ± {_num(p['sd'], p['unit'])}"
    text += f", n = {p['n']}" if p["n"] > 1 else ""
    if p["failed"]:
        text += f" ({p['failed']} diverged/failed)"
    return text


def _best(b: dict[str, Any] | None, unit: str) -> str:
    if not b:
        return "—"
    s = b["settings"]
    brief = ", ".join(
        f"{k}={v}"
        for k, v in s.items()
        if k in ("hidden", "activation", "ny", "nu", "ne", "nk", "degree", "rho_p", "linear", "lr", "units")
    )
    return f"{_num(b['value'], unit)} ({b['identifier']}{': ' + brief if brief else ''})"


def _budget(r: dict[str, Any]) -> str:
    s = r["settings"]
    parts = [f"{s['epochs']} ep" if "epochs" in s else None, f"{r['project']['n']} run(s)"]
    return ", ".join(p for p in parts if p)


def full_tier_cost(rows: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """CPU seconds of the full tier, from the stored per-fit CPU times scaled to the full tier's epochs (training
    time taken as proportional to the epochs) and multiplied by its number of fits; plus Table 5.3's grid."""
    from benchmarks.thesis.runner import ROW_IDS, tasks_for

    full = TIERS["full"]
    per: dict[str, list[float]] = {}
    for r in rows.values():
        tier = r["measured"].get("tier", {})
        pre = r.get("preset") or {}
        for f in r["fits"] + r.get("other_fits", []) + pre.get("fits", []) + pre.get("other_fits", []):
            if f["cpu_seconds"] is None:
                continue
            key = f["key"]
            bare = key.removeprefix("preset/")
            field = next((v for k, v in _EPOCH_FIELD.items() if bare.startswith(k)), None)
            if bare.startswith("cant/peak"):
                field = None
            scale = getattr(full, field) / tier[field] if field and tier.get(field) else 1.0
            per.setdefault(key.rsplit("/", 1)[0] if key.rsplit("/", 1)[-1].isdigit() else key, []).append(
                f["cpu_seconds"] * scale
            )
    total, missing, n_fits = 0.0, [], 0
    for key in tasks_for(ROW_IDS, full):
        group = key.rsplit("/", 1)[0] if key.rsplit("/", 1)[-1].isdigit() else key
        n_fits += 1
        if group in per:
            total += float(np.mean(per[group]))
        else:
            missing.append(group)
    ds2 = [v for k, vals in per.items() if k.removeprefix("preset/").startswith("ds2/") for v in vals]
    g = GRID_5_3
    n_grid = g["lags"] ** 2 * g["layers"] * g["widths"] * g["activations"]
    grid_cpu = n_grid * g["runs"] * float(np.mean(ds2)) if ds2 else None
    return {
        "fits": n_fits,
        "cpu_seconds": total,
        "missing": sorted(set(missing)),
        "grid_configurations": n_grid,
        "grid_cpu_seconds": grid_cpu,
        "ds2_fit_cpu_seconds": float(np.mean(ds2)) if ds2 else None,
    }


def _hours(s: float) -> str:
    return f"{s / 3600:.1f}" if s >= 360 else f"{s / 3600:.2f}"


def render(rows: dict[str, dict[str, Any]], histogram: str | None = None, grid: dict[str, Any] | None = None) -> str:
    """The whole page (Markdown) from the stored rows (and Table 5.3's stored sample, ``grid``)."""
    out = [
        "# The dissertation, table by table",
        "",
        "<!-- generated by `piezotwin thesis --render-only` from docs/dissertation/rows.json: do not edit -->",
        "",
        "Each row puts one published figure of the dissertation (Chapters 3–5) beside the project's measurement "
        "of it on the twins, with every way the protocol differs, the command that measures the row again, and "
        "the project's best model on the same protocol. Verdicts: **within** the published spread (± one "
        "published SD, the range of the published runs, or the range of the table's rows where no SD is "
        "printed; see the notes), **better**, **below** (or **outside** for frequencies), **failed**. Rows are "
        "measured by `piezotwin thesis --store` and this page is rendered from `docs/dissertation/rows.json` "
        "by `piezotwin thesis --render-only`.",
        "",
    ]
    out += ["## Slips in the dissertation's numbers", ""] + [f"- {s}" for s in targets.SLIPS] + [""]
    out += [
        "## Summary",
        "",
        "Default twin: the twins as they are; thesis preset: the rigs as the dissertation's text describes them "
        "(see [The thesis preset](#the-thesis-preset)), measured for Chapter 5 and Figure 3.4.",
        "",
        "| item | rows | within | better | below / outside | failed | CPU s | preset: within | better | below / "
        "outside | failed | CPU s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    totals: dict[str, list[int]] = {}
    for fam, title in _TITLES.items():
        rs = [r for rid, r in rows.items() if rid.startswith(fam + "/")]
        if not rs:
            continue
        out.append(f"| {title.split(' — ')[0]} | {len(rs)} | {_counts(rs)} | {_counts(rs, True)} |")
        ch = "5" if fam.split("-")[1].startswith("5") else fam
        agg = totals.setdefault(ch, [0, 0, 0])
        agg[0] += len(rs)
        agg[1] += sum(r["verdict"] in ("within", "better") for r in rs)
        agg[2] += sum((r.get("preset") or {}).get("verdict") in ("within", "better") for r in rs)
    if "5" in totals:
        n, d, p = totals["5"]
        out += [
            "",
            f"Chapter 5: {d} of {n} rows within the published spread or better on the default twin, "
            f"{p} of {n} on the thesis preset.",
        ]
    missing = [rid for rid in targets.TARGETS if rid not in rows]
    out += [
        "",
        f"{len(rows)} rows stored, {len(missing)} not measured yet"
        + (f" ({', '.join(missing)})" if missing else "")
        + ".",
        "",
    ]
    for fam, title in _TITLES.items():
        rs = [r for rid, r in rows.items() if rid.startswith(fam + "/")]
        if rs:
            out += _section(title, rs, histogram if fam == "fig-5.13" else None)
    out += _preset_section() + _grid_section(grid, rows) + _cost_section(rows) + _measurements(rows)
    return "\n".join(out).rstrip() + "\n"


def _counts(rs: list[dict[str, Any]], preset: bool = False) -> str:
    """``within | better | below/outside | failed | CPU s`` of the rows (or of their preset parts)."""
    parts = [r.get("preset") for r in rs] if preset else rs
    ok = [p for p in parts if p]
    if not ok:
        return "— | — | — | — | —"
    count = {v: sum(p["verdict"] == v for p in ok) for v in ("within", "better", "below", "outside", "failed")}
    cpu = sum({f["key"]: f["cpu_seconds"] or 0.0 for p in ok for f in p["fits"]}.values())
    return (
        f"{count['within']} | {count['better']} | {count['below'] + count['outside']} | {count['failed']} | {cpu:.0f}"
    )


def _grid_section(grid: dict[str, Any] | None, rows: dict[str, dict[str, Any]]) -> list[str]:
    """Table 5.3's sample (:mod:`benchmarks.thesis.grid`): its size, each configuration, the best beside the
    dissertation's choice."""
    if not grid:
        return []
    cs = grid["configurations"]
    out = [
        "## Table 5.3 — a random sample of the grid",
        "",
        f"{grid['sample_size']} of the grid's {grid['grid_size']:,} configurations (n_u, n_y, depth, one width, "
        f"activation), drawn uniformly without replacement with `numpy.random.default_rng({grid['seed']})`, each "
        f"trained {grid['runs_per_configuration']} times (§5.2: 'each model was run twice') at "
        f"{grid['epochs']} epochs on {grid['data']}; means over the runs, {grid['cpu_seconds']:.0f} CPU s in all "
        f"(measured {grid['measured'].get('date', '?')}, {grid['measured'].get('process', '?')}). "
        "Reproduce: `piezotwin thesis --grid-sample "
        f"{grid['sample_size']} --grid-seed {grid['seed']} --store`; the whole grid: `--grid-sample all "
        "--scheduler ADDRESS` on a Dask cluster.",
        "",
        "| n_u | n_y | hidden | activation | parameters | estimation FRS R² | validation FRS R² | one-step R² "
        "(est; val) | CPU s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c in sorted(cs, key=lambda c: -(c["r2_frs_est"] if c["r2_frs_est"] is not None else -math.inf)):
        out.append(
            f"| {c['nu']} | {c['ny']} | {'-'.join(map(str, c['hidden']))} | {c['activation']} | "
            f"{c['n_parameters']} | {_num(c['r2_frs_est'])} | {_num(c['r2_frs_val'])} | "
            f"{_num(c['r2_osa_est'])}; {_num(c['r2_osa_val'])} | {c['cpu_seconds']:.1f} |"
        )
    per = grid["cpu_seconds"] / max(len(cs), 1)
    whole = per * grid["grid_size"]
    out += [
        "",
        f"Cost of the whole grid, estimated from this uniform sample (an unbiased estimate of the mean over the "
        f"grid): {per:.1f} CPU s per configuration ({grid['runs_per_configuration']} runs) × "
        f"{grid['grid_size']:,} = **{_hours(whole)} CPU-hours**, {_hours(whole / 32)} h of wall time on 32 "
        "workers (`--grid-sample all --scheduler ADDRESS`); the sample's CPU times were measured on "
        f"{_machine(grid['measured'])}.",
    ]
    best = next((c for c in cs if c["label"] == grid.get("best")), None)
    if best:
        out += [
            "",
            f"Best of the sample by estimation FRS R² (the dissertation chose on estimation, §5.2): n_u = "
            f"{best['nu']}, n_y = {best['ny']}, {'-'.join(map(str, best['hidden']))} {best['activation']}: "
            f"{_num(best['r2_frs_est'])} estimation, {_num(best['r2_frs_val'])} validation. The dissertation's "
            f"choice (n_u = n_y = 512, 75-75 sigmoid) on the same data: {_choice(rows)}.",
        ]
    validated = [c for c in cs if c["r2_frs_est"] is not None and c["r2_frs_val"] is not None]
    if best and best["r2_frs_val"] is None and validated:
        b2 = max(validated, key=lambda c: c["r2_frs_est"])
        out.append(
            f"A validation R² of '—': the regressor is longer than the 1000-sample validation record (§3.2's "
            f"truncation). The best of the sample that can be validated: n_u = {b2['nu']}, n_y = {b2['ny']}, "
            f"{'-'.join(map(str, b2['hidden']))} {b2['activation']}: {_num(b2['r2_frs_est'])} estimation, "
            f"{_num(b2['r2_frs_val'])} validation."
        )
    return out + [""]


def _machine(m: dict[str, Any]) -> str:
    mach = m.get("machine") or {}
    load = m.get("load_average_before")
    text = f"{mach.get('cpu', '?')}, {mach.get('cores', '?')} cores"
    return text + (f", load average {load[0]:.1f} before the run" if load else "")


def _choice(rows: dict[str, dict[str, Any]]) -> str:
    """The preset's Table 5.4 / 5.5 values of the dissertation's chosen network, as stored."""
    parts = []
    for fam, what in (("table-5.4", "estimation"), ("table-5.5", "validation")):
        p = (rows.get(f"{fam}/{targets.BEST_DS2}") or {}).get("preset")
        if p:
            parts.append(f"{_project(p['project'])} {what} ({fam.replace('table-', 'Table ')})")
    return ", ".join(parts) if parts else "not measured on the preset yet"


def _preset_section() -> list[str]:
    from benchmarks.thesis.preset import CHOICES, HOW_CHOSEN

    out = [
        "## The thesis preset",
        "",
        "A named parameter set of the twins (`benchmarks/thesis/preset.py`), used by `piezotwin thesis` only; the "
        "twins' defaults and every accuracy floor stay as they are. Each choice and the passage it comes from "
        "(none is fitted to a row's R²; how two of them were chosen is said below the table):",
        "",
        "| choice | passage |",
        "|---|---|",
    ]
    return out + [f"| {c} | {p} |" for c, p in CHOICES] + ["", HOW_CHOSEN, ""]


def _section(title: str, rs: list[dict[str, Any]], histogram: str | None) -> list[str]:
    if any(r.get("preset") for r in rs):
        out = [
            f"## {title}",
            "",
            "| row | dissertation | thesis preset (mean ± SD, n) | verdict | default twin (mean ± SD, n) | verdict | "
            "project's best on this protocol (preset; default twin) | budget | CPU s (preset; default) |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rs:
            unit, p = r["dissertation"]["unit"], r.get("preset") or {}
            pre = (_project(p["project"]), p["verdict"], _best(p.get("best"), unit)) if p else ("—", "—", "—")
            cpu = f"{p['cpu_seconds']:.1f}; " if p else "—; "
            out.append(
                f"| `{r['id']}` | {_dissertation(r['dissertation'])} | {pre[0]} | {pre[1]} | "
                f"{_project(r['project'])} | {r['verdict']} | {pre[2]}; {_best(r['best'], unit)} | {_budget(r)} | "
                f"{cpu}{r['cpu_seconds']:.1f} |"
            )
    else:
        out = [
            f"## {title}",
            "",
            "| row | dissertation | project (mean ± SD, n) | verdict | project's best on this protocol | budget | "
            "CPU s |",
            "|---|---|---|---|---|---|---|",
        ]
        for r in rs:
            unit = r["dissertation"]["unit"]
            out.append(
                f"| `{r['id']}` | {_dissertation(r['dissertation'])} | {_project(r['project'])} | {r['verdict']} | "
                f"{_best(r['best'], unit)} | {_budget(r)} | {r['cpu_seconds']:.1f} |"
            )
    spreads: dict[str, list[str]] = {}
    for r in rs:
        spreads.setdefault(r["dissertation"]["note"] or "± one published SD", []).append(r["id"])
    text = "; ".join(k if len(spreads) == 1 else f"{k} ({', '.join(v)})" for k, v in spreads.items())
    out += ["", f"Metric: {rs[0]['metric']}. Published spread: {text}.", ""]
    if any(r.get("preset") for r in rs):
        out += [
            "Thesis preset column: the same protocol, seeds and budget on the preset's twin and acquisition (the "
            "choices in [The thesis preset](#the-thesis-preset)); the differences below are the default twin's, "
            "and hold for the preset except where a choice there replaces them.",
            "",
        ]
    seen: list[list[str]] = []
    for r in rs:
        if r["differences"] not in seen:
            seen.append(r["differences"])
    for diffs in seen:
        ids = [r["id"] for r in rs if r["differences"] == diffs]
        head = "Protocol differences" + ("" if len(seen) == 1 else f" ({', '.join(ids)})")
        out += [f"{head}:", ""] + [f"- {d}" for d in diffs] + [""]
    notes: dict[str, list[str]] = {}
    for r in rs:
        note = r.get("explanation") or (f"this fit: {r['settings']['note']}" if r["settings"].get("note") else None)
        if note:
            notes.setdefault(str(note), []).append(f"`{r['id']}` ({r['verdict']})")
    if notes:
        out += ["Measured explanations (default twin):", ""]
        out += [f"- {', '.join(ids)}: {text}" for text, ids in notes.items()] + [""]
    pnotes: dict[str, list[str]] = {}
    for r in rs:
        p = r.get("preset") or {}
        if p.get("explanation"):
            pnotes.setdefault(str(p["explanation"]), []).append(f"`{r['id']}` ({p['verdict']})")
    if pnotes:
        out += ["Measured explanations (thesis preset):", ""]
        out += [f"- {', '.join(ids)}: {text}" for text, ids in pnotes.items()] + [""]
    cmds = sorted({r["command"].replace(r["id"], fam_of(r["id"])) for r in rs})
    out += ["Reproduce: " + "; ".join(f"`{c}`" for c in cmds) + " (or one row: `--rows " + rs[0]["id"] + "`).", ""]
    if histogram:
        out += [f"![Figure 5.13 analogue: FRS R² over the runs]({histogram})", ""]
    return out


def fam_of(rid: str) -> str:
    return rid.split("/")[0]


def _cost_section(rows: dict[str, dict[str, Any]]) -> list[str]:
    c = full_tier_cost(rows)
    out = [
        "## Cost of the full tier",
        "",
        "The full tier is the dissertation's budget: Table 4.1's 100 epochs and Table 5.3's 75, 5 runs per "
        "network, Table 5.6's 5 runs and Figure 5.13's 75. Estimated from the CPU seconds of the fits stored "
        "above (each scaled to the full tier's epochs, training time taken as proportional to the epochs), "
        f"times the full tier's {c['fits']} fits:",
        "",
    ]
    if c["missing"]:
        out.append(f"- not yet estimable (no stored fit of): {', '.join(c['missing'])}")
    cpu = c["cpu_seconds"]
    out += [
        f"- **{_hours(cpu)} CPU-hours**; wall time about {_hours(cpu / 2)} h on 2 cores (`--workers 2`), "
        f"{_hours(cpu / 8)} h with `--workers 8`, {_hours(cpu / 32)} h with 32 workers (`--scheduler`), if the "
        "fits spread evenly (the longest single fit bounds the wall time from below)."
    ]
    if c["grid_cpu_seconds"] is not None:
        g = GRID_5_3
        out.append(
            f"- Table 5.3's grid at full size, one width for every layer ({g['lags']} lag values for n_u and "
            f"for n_y, {g['layers']} depths, {g['widths']} widths, {g['activations']} activations: "
            f"{c['grid_configurations']:,} configurations, {g['runs']} runs each, as §5.2 ran them), at the "
            f"mean CPU time of the data-set-2 fits above ({c['ds2_fit_cpu_seconds']:.1f} s at 75 epochs): "
            f"**{_hours(c['grid_cpu_seconds'])} CPU-hours** — wide and deep networks with 1024 lags cost "
            "more than the eight measured, so this is a lower bound (the random sample of the grid above, where "
            "stored, estimates the grid's mean directly); "
            f"{_hours(c['grid_cpu_seconds'] / 32)} h of wall time on 32 workers."
        )
    out += [
        "- `piezotwin thesis --tier full --workers N` (or `--scheduler ADDRESS`) runs the full tier; "
        "`piezotwin search` sweeps the grid itself on shared Optuna storage.",
        "",
    ]
    return out


def _measurements(rows: dict[str, dict[str, Any]]) -> list[str]:
    groups: dict[str, list[str]] = {}
    info: dict[str, dict[str, Any]] = {}
    for rid, r in rows.items():
        m = r["measured"]
        key = f"{m.get('date', '?')}|{(m.get('tier') or {}).get('name', '?')}"
        groups.setdefault(key, []).append(rid)
        info[key] = m
    out = [
        "## How the rows were measured",
        "",
        "Each line is one `piezotwin thesis` run (wall seconds of the whole run with all its fits, where the row "
        "recorded it; CPU seconds per fit are in the tables above).",
        "",
        "| date (UTC) | tier | rows | machine | load (1 min) before → after | process | wall s | versions |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for key, ids in groups.items():
        m = info[key]
        mach = m.get("machine") or {}
        fams = sorted({fam_of(i) for i in ids})
        load = " → ".join(f"{(m.get(k) or [math.nan])[0]:.1f}" for k in ("load_average_before", "load_average_after"))
        versions = ", ".join(f"{k} {v}" for k, v in (m.get("versions") or {}).items() if v and k != "sysidentpy")
        out.append(
            f"| {m.get('date', '?')} | {(m.get('tier') or {}).get('name', '?')} | {len(ids)} "
            f"({', '.join(fams)}) | {mach.get('cpu', '?')}, {mach.get('cores', '?')} cores | {load} | "
            f"{m.get('process', '?')} | {_num(m.get('wall_seconds'), digits=0)} | {versions} |"
        )
    return out + [""]


def write_histogram(rows: dict[str, dict[str, Any]], path: str | Path) -> Path | None:
    """Figure 5.13 analogue: histograms of the stored FRS R² runs (estimation, validation) with the dissertation's
    mean ± SD; ``None`` when the rows are not stored."""
    est, val = rows.get("fig-5.13/est"), rows.get("fig-5.13/val")
    if not (est and val):
        return None
    from sysid.report.plots import pyplot, save_and_close

    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for ax, r, title in ((axes[0], est, "estimation"), (axes[1], val, "validation")):
        v = [x for x in r["project"]["values"] if x is not None]
        d = r["dissertation"]
        ax.hist(v, bins=min(20, max(5, len(v) // 2)), color="tab:blue", alpha=0.6, label=f"default twin, {len(v)} runs")
        pre = r.get("preset")
        if pre:
            w = [x for x in pre["project"]["values"] if x is not None]
            ax.hist(
                w,
                bins=min(20, max(5, len(w) // 2)),
                color="tab:green",
                alpha=0.6,
                label=f"thesis preset, {len(w)} runs",
            )
        for x, ls in ((d["value"], "-"), (d["value"] - d["sd"], ":"), (d["value"] + d["sd"], ":")):
            ax.axvline(x, color="tab:red", ls=ls)
        ax.plot([], [], color="tab:red", label=f"dissertation {d['value']:.3f} ± {d['sd']:.3f} (n = {d['n']})")
        ax.set_title(f"FRS R², {title}")
        ax.set_xlabel("R²")
        ax.legend(fontsize=8)
    fig.tight_layout()
    return save_and_close(fig, path, metadata={"Software": None})
