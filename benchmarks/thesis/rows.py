"""Stored rows of ``piezotwin thesis``: their format, how they are built from fit results, stored and read back.

A row (format :data:`ROW_FORMAT`) holds one published figure beside the project's measurement of it:

- ``id`` (``table-4.2/4x25``), ``item`` (the table or figure), ``metric``;
- ``dissertation``: ``value``, ``sd``, ``n``, ``low``/``high`` (the spread the project is judged against), ``unit``,
  ``note``;
- ``project``: ``mean``, ``sd``, ``n`` (repeats), ``values`` (one per repeat; ``null`` for a diverged free run),
  ``failed``, ``unit``; ``verdict``: ``within`` / ``better`` / ``below`` / ``outside`` / ``failed``;
- ``settings`` (epochs, repeats, records) and ``differences`` (every way the protocol differs, one string each);
- ``command`` (reproduces the row), ``best`` (the project's best model on the same protocol: ``value``,
  ``identifier``, ``settings``), ``explanation`` (measured statements only, or ``null``);
- ``fits`` (per fit: key, CPU and wall seconds), ``cpu_seconds`` (their sum) and ``measured`` (date, machine,
  versions, load, tier);
- ``preset`` (Chapter 5's rows and Figure 3.4, when measured on the thesis preset too): ``name``, ``project``,
  ``verdict``, ``settings``, ``best``, ``fits``, ``cpu_seconds``, ``explanation`` of the same row on
  :mod:`benchmarks.thesis.preset` (the keys above stay those of the default twin).

The whole file (``docs/dissertation/rows.json``) maps ids to rows; the page is rendered from it alone
(:mod:`benchmarks.thesis.page`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.thesis import explain, targets
from benchmarks.thesis.plan import Tier
from sysid.errors import ConfigError

__all__ = ["ROW_FORMAT", "FILE_FORMAT", "build_row", "write_rows", "load_rows", "check_row", "stats"]

ROW_FORMAT = "piezotwin-thesis-row/1"
FILE_FORMAT = "piezotwin-thesis-rows/1"
_METRIC = {
    "table-4.2": "mean over the 12 sines of the validation FRS R²",
    "table-4.3": "validation FRS R² of the sine",
    "table-5.2": "FRS R² on the estimation data (data set 1)",
    "table-5.4": "estimation FRS R² (data set 2)",
    "table-5.5": "validation FRS R² (data set 2, 1 ms chirp)",
    "fig-3.4": "output-spectrum peak above 500 Hz",
    "fig-3.9": "transmission peak of the gated VNA response",
}


def stats(values: list[float | None]) -> dict[str, Any]:
    """mean, SD (n−1), n of the finite values; ``failed`` counts the rest (diverged free runs, refused fits)."""
    ok = [float(v) for v in values if v is not None and math.isfinite(v)]
    return {
        "mean": float(np.mean(ok)) if ok else None,
        "sd": float(np.std(ok, ddof=1)) if len(ok) > 1 else None,
        "n": len(values),
        "failed": len(values) - len(ok),
        "values": [float(v) if v is not None and math.isfinite(v) else None for v in values],
    }


def _verdict(mean: float | None, tg: targets.Target) -> str:
    if mean is None:
        return "failed"
    if tg.low <= mean <= tg.high:
        return "within"
    if not tg.higher_is_better:
        return "outside"
    return "better" if mean > tg.high else "below"


def _runs(results: dict[str, dict[str, Any]], prefix: str, n: int | None = None) -> list[tuple[str, dict]]:
    def seed(kv: tuple[str, dict]) -> int:
        last = kv[0].rsplit("/")[-1]
        return int(last) if last.isdigit() else 0

    hits = sorted(((k, v) for k, v in results.items() if k.startswith(prefix)), key=seed)
    return hits if n is None else hits[:n]


def _mean_of(results, prefix: str, key: str) -> float | None:
    return stats([r.get(key) for _, r in _runs(results, prefix)])["mean"]


def _best(candidates: list[tuple[float | None, str, dict[str, Any], int]], higher: bool = True) -> dict | None:
    ok = [(float(c[0]), *c[1:]) for c in candidates if c[0] is not None and math.isfinite(c[0])]
    if not ok:
        return None
    v, ident, settings, n = max(ok, key=lambda c: c[0]) if higher else ok[0]
    return {"value": v, "identifier": ident, "settings": settings, "n": n}


def _command(rid: str, t: Tier) -> str:
    tier = " --quick" if t.name == "quick" else ("" if t.name == "middle" else f" --tier {t.name}")
    return f"piezotwin thesis --rows {rid}{tier} --store"


def build_row(rid: str, results: dict[str, dict[str, Any]], t: Tier, measured: dict[str, Any]) -> dict[str, Any]:
    """One row from the fit results (key -> result, see :func:`benchmarks.thesis.runner.tasks_for`)."""
    fam, name = rid.split("/", 1)
    tg = targets.TARGETS[rid]
    builder = {
        "table-4.2": _cantilever,
        "table-4.3": _cantilever,
        "table-5.2": _ds1,
        "table-5.4": _ds2,
        "table-5.5": _ds2,
        "table-5.6": _ds2,
        "fig-5.13": _ds2,
        "fig-3.4": _peaks,
        "fig-3.9": _peaks,
    }[fam]
    values, fits, settings, best = builder(fam, name, results, t)
    proj = {**stats(values), "unit": tg.unit}
    row: dict[str, Any] = {
        "format": ROW_FORMAT,
        "id": rid,
        "item": tg.source,
        "metric": _METRIC.get(fam, _METRIC_6.get(name, "")),
        "dissertation": {
            "value": tg.value,
            "sd": tg.sd,
            "n": tg.n,
            "low": tg.low,
            "high": tg.high,
            "unit": tg.unit,
            "note": tg.note,
            **({"runs": tg.extra["runs"]} if "runs" in tg.extra else {}),
        },
        "project": proj,
        "verdict": _verdict(proj["mean"], tg),
        "settings": settings,
        "differences": explain.differences(fam, t),
        "command": _command(rid, t),
        "best": best,
        "fits": [_fit(k, r) for k, r in fits],
        "other_fits": [_fit(k, r) for k, r in sorted(results.items()) if k.startswith(_OTHER.get(fam, "\0"))],
        "measured": {
            k: measured[k]
            for k in (
                "date",
                "machine",
                "versions",
                "load_average_before",
                "load_average_after",
                "process",
                "tier",
                "wall_seconds",
            )
            if k in measured
        },
    }
    row["cpu_seconds"] = float(sum(f["cpu_seconds"] or 0.0 for f in row["fits"]))
    row["explanation"] = explain.explanation(row, results, t)
    pre = _preset_part(rid, builder, results, t, tg)
    if pre is not None:
        row["preset"] = pre
    return row


def _preset_part(rid: str, builder, results: dict[str, dict[str, Any]], t: Tier, tg) -> dict[str, Any] | None:
    """The same row built from the thesis preset's fits (keys ``preset/...``), or ``None`` without them."""
    from benchmarks.thesis import preset

    prefix = "preset/"
    sub = {k[len(prefix) :]: v for k, v in results.items() if k.startswith(prefix)}
    fam, name = rid.split("/", 1)
    try:
        values, fits, settings, best = builder(fam, name, sub, t)
    except (KeyError, IndexError):  # no preset fit of this row in this run
        return None
    if not fits:
        return None
    proj = {**stats(values), "unit": tg.unit}
    part: dict[str, Any] = {
        "name": preset.NAME,
        "project": proj,
        "verdict": _verdict(proj["mean"], tg),
        "settings": settings,
        "best": best,
        "fits": [_fit(prefix + k, r) for k, r in fits],
        "other_fits": [_fit(prefix + k, r) for k, r in sorted(sub.items()) if k.startswith(_OTHER.get(fam, "\0"))],
    }
    part["cpu_seconds"] = float(sum(f["cpu_seconds"] or 0.0 for f in part["fits"]))
    part["explanation"] = explain.preset_explanation(rid, part, sub, t)
    return part


#: the fits of the project's other models beside a family's rows (the "best" column, the explanations)
_OTHER = {
    "table-4.2": "cant-cand/",
    "table-4.3": "cant-",
    "table-5.2": "ds1-cand/",
    "table-5.4": "ds2-",
    "table-5.5": "ds2-",
    "table-5.6": "ds2-",
    "fig-5.13": "ds2-",
}


def _fit(key: str, r: dict[str, Any]) -> dict[str, Any]:
    return {"key": key, "cpu_seconds": r.get("cpu_seconds"), "wall_seconds": r.get("wall_seconds")}


_METRIC_6 = {
    "osa-est": "one-step R² on the estimation data",
    "frs-est": "FRS R² on the estimation data",
    "osa-val": "one-step R² on the validation data",
    "frs-val": "FRS R² on the validation data",
    "est": "FRS R² on the estimation data, over the runs",
    "val": "FRS R² on the validation data, over the runs",
    "peak": "largest peak",
    "second-peak": "second peak",
}


def _cantilever(fam, name, results, t: Tier):
    arch = "4x25" if fam == "table-4.3" else name
    runs = _runs(results, f"cant/{arch}/")
    key = "r2_mean" if fam == "table-4.2" else None
    freq = name[:-2] if fam == "table-4.3" else None
    values = [r[key] if key else r["r2_per_freq"].get(freq) for _, r in runs]
    settings = {
        "network": f"{arch.replace('x', ' × ')} ReLU, n_y = n_u = 10",
        "epochs": t.cantilever_epochs,
        "repeats": t.cantilever_repeats,
        "estimation_s": t.cantilever_duration_s or 8.0,
    }
    cands = []
    for layers, width in targets.TABLE_4_2:
        rr = _runs(results, f"cant/{layers}x{width}/")
        if rr:
            vals = [r[key] if key else r["r2_per_freq"].get(freq) for _, r in rr]
            cands.append(
                (stats(vals)["mean"], "narx-mlp", {"hidden": f"{layers} × {width}", "activation": "relu"}, len(rr))
            )
    for ident in ("narx-poly", "narx-mlp"):
        rr = _runs(results, f"cant-cand/{ident}/")
        if rr:
            vals = [r[key] if key else r["r2_per_freq"].get(freq) for _, r in rr]
            cands.append((stats(vals)["mean"], ident, rr[0][1]["params"], len(rr)))
    return values, runs, settings, _best(cands)


def _ds1(fam, name, results, t: Tier):
    runs = _runs(results, f"ds1/{name}/")
    values = [r["r2_frs"] for _, r in runs]
    first = runs[0][1]
    settings = {
        "identifier": first["identifier"],
        **{k: v for k, v in first["params"].items() if k != "seed"},
        "repeats": len(runs),
    }
    notes = sorted({r["note"] for _, r in runs if r.get("note")})
    if notes:
        settings["note"] = "; ".join(notes)
    cands = []
    for line in targets.TABLE_5_2:
        rr = _runs(results, f"ds1/{targets.table_5_2_id(*line[:5]).split('/', 1)[1]}/")
        if rr:
            cands.append(
                (
                    stats([r["r2_frs"] for _, r in rr])["mean"],
                    rr[0][1]["identifier"],
                    {k: v for k, v in rr[0][1]["params"].items() if k != "seed"},
                    len(rr),
                )
            )
    groups: dict[str, list[dict[str, Any]]] = {}
    for key, r in results.items():
        if key.startswith("ds1-cand/"):
            groups.setdefault(key.rsplit("/", 1)[0] if key.rsplit("/", 1)[1].isdigit() else key, []).append(r)
    for rr2 in groups.values():
        cands.append(
            (
                stats([r["r2_frs"] for r in rr2])["mean"],
                rr2[0]["identifier"],
                {k: v for k, v in rr2[0]["params"].items() if k != "seed"},
                len(rr2),
            )
        )
    return values, runs, settings, _best(cands)


def _ds2(fam, name, results, t: Tier):
    BEST_DS2, _ARCH = targets.BEST_DS2, targets.ARCH
    if fam in ("table-5.4", "table-5.5"):  # the 75-75 network also has Fig. 5.13's runs: the tier's repeats here
        arch, key, n = name, explain.DS2_KEYS[fam], t.acoustic_repeats
    else:
        arch, key = BEST_DS2, explain.DS2_KEYS[name]
        n = t.table_5_6_runs if fam == "table-5.6" else t.fig_5_13_runs
    runs = _runs(results, f"ds2/{arch}/", n)
    values = [r[key] for _, r in runs]
    ny, hidden, act = _ARCH[arch]
    settings = {
        "network": f"{'-'.join(map(str, hidden))} {act}, n_u = 512, n_y = {ny}",
        "epochs": t.acoustic_epochs,
        "repeats": len(runs),
    }
    cands = []
    for lab, (ny2, hid2, act2) in _ARCH.items():
        rr = _runs(results, f"ds2/{lab}/")
        if rr:
            cands.append(
                (
                    stats([r[key] for _, r in rr])["mean"],
                    "narx-mlp",
                    {"hidden": "-".join(map(str, hid2)), "activation": act2, "ny": ny2, "nu": 512},
                    len(rr),
                )
            )
    rr = _runs(results, "ds2-cand/")
    if rr:
        p = rr[0][1]["params"]
        cands.append(
            (
                stats([r[key] for _, r in rr])["mean"],
                "narx-mlp",
                {
                    "hidden": "-".join(map(str, p["hidden"])),
                    "activation": p["activation"],
                    "ny": p["ny"],
                    "nu": p["nu"],
                    "nk": p["nk"],
                },
                len(rr),
            )
        )
    return values, runs, settings, _best(cands)


def _peaks(fam, name, results, t: Tier):
    if fam == "fig-3.4":
        r = results["cant/peak"]
        return (
            [r["peak_hz"]],
            [("cant/peak", r)],
            {"record": "thesis-multisine, 8 s at 10 kHz, Welch 1 s Hann", "level_db": r["peak_rel_db"]},
            None,
        )
    r = results["vna/peaks"]
    i = 0 if name == "peak" else 1
    val = r["peaks_hz"][i] if len(r["peaks_hz"]) > i else None
    return (
        [val],
        [("vna/peaks", r)],
        {
            "record": "vna-sweep gated, 900–1350 kHz, 1 kHz grid",
            "level_db": r["levels_db"][i] if val is not None else None,
        },
        None,
    )


# ------------------------------------------------------------------------------------------------ storage
def check_row(row: Any, where: str = "") -> dict[str, Any]:
    """A stored row, or a ConfigError naming what is missing."""
    need = (
        "id",
        "item",
        "dissertation",
        "project",
        "verdict",
        "settings",
        "differences",
        "command",
        "fits",
        "cpu_seconds",
        "measured",
    )
    if not (isinstance(row, dict) and row.get("format") == ROW_FORMAT and all(k in row for k in need)):
        raise ConfigError(f"{where}: not a stored thesis row (format {ROW_FORMAT!r} with {', '.join(need)})")
    if row["id"] not in targets.TARGETS:
        raise ConfigError(f"{where}: unknown row id {row['id']!r}")
    return row


def load_rows(path: str | Path) -> dict[str, dict[str, Any]]:
    """The stored rows (id -> row) of ``path``; an absent file holds none."""
    path = Path(path)
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the stored thesis rows ({exc})") from None
    if not (isinstance(data, dict) and data.get("format") == FILE_FORMAT and isinstance(data.get("rows"), dict)):
        raise ConfigError(f"{path}: not a thesis rows file (format {FILE_FORMAT!r} with rows)")
    return {rid: check_row(r, f"{path}: {rid}") for rid, r in data["rows"].items()}


def write_rows(rows: dict[str, dict[str, Any]], path: str | Path) -> Path:
    """Store ``rows`` (merged over the rows already stored there, in the page's order), atomically."""
    from sysid.data.jsonio import clean_json
    from sysid.data.safeio import atomic_write_text

    path = Path(path)
    merged = {**load_rows(path), **rows}
    ordered = {rid: merged[rid] for rid in targets.TARGETS if rid in merged}
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(
        path, json.dumps(clean_json({"format": FILE_FORMAT, "rows": ordered}), indent=1, ensure_ascii=False) + "\n"
    )
    return path
