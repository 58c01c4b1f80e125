"""Accuracy baselines: the floors of ``benchmarks/baselines.json``, the regression check against them, and
measuring new floors.

:func:`check` compares a run against the baselines: per (identifier, dataset, test) a ceiling on free-run RMSE
(a floor on accuracy), plus the project's rules — every nonlinear identifier beats the linear baseline (ARX in the
same run, and the published BLA) on every nonlinear dataset, and the polynomial NARMAX beats SysIdentPy's published
Silverbox numbers. :func:`make_floors` measures floors from one or more runs.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from benchmarks.scoring.core import ScoreRun, _finite, _fmt
from benchmarks.scoring.settings import QUICK_SEEDS
from sysid.errors import ConfigError
from sysid.registry import LINEAR_IDENTIFIERS

BASELINES_PATH = Path(__file__).resolve().parent.parent / "baselines.json"
BASELINES_FORMAT = "piezotwin-baselines/1"


def load_baselines(path: str | Path | None = None) -> dict[str, Any]:
    """The baselines file (default :data:`BASELINES_PATH`). A file that is missing, unreadable, not JSON or not of
    :data:`BASELINES_FORMAT` raises :class:`ConfigError` (one line: the CLI exits 2) — a check without floors would
    pass anything."""
    p = Path(path) if path else BASELINES_PATH
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise ConfigError(f"{p}: baselines file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: baselines file cannot be read ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"{p}: baselines file is not JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(data, dict) or data.get("format") != BASELINES_FORMAT:
        got = data.get("format") if isinstance(data, dict) else type(data).__name__
        raise ConfigError(f"{p}: not a baselines file (format {got!r}, expected {BASELINES_FORMAT!r})")
    modes, rules = data.get("modes", {}), data.get("rules", [])
    if (
        not isinstance(modes, dict)
        or not all(isinstance(m, dict) for m in modes.values())
        or not isinstance(rules, list)
    ):
        raise ConfigError(f"{p}: baselines file malformed: 'modes' must map a mode to floors and 'rules' be a list")
    for mode, floors in modes.items():
        for ident, dsets in floors.items():
            for dname, tests in dsets.items() if isinstance(dsets, dict) else [(None, None)]:
                for test, f in tests.items() if isinstance(tests, dict) else [(None, None)]:
                    if not (isinstance(f, dict) and _finite(f.get("max_rmse")) and f["max_rmse"] > 0):
                        raise ConfigError(
                            f"{p}: baselines file malformed: floor {mode}/{ident}/{dname}/{test} needs a "
                            "finite positive 'max_rmse'"
                        )
    return data


def dropped_pairs(baselines: dict[str, Any], mode: str) -> dict[tuple[str, str, str], str]:
    """Pairs taken out of the check on purpose (``dropped``: identifier, dataset, test or ``*``, reason)."""
    out = {}
    for e in baselines.get("dropped", {}).get(mode, []):
        out[(e["identifier"], e["dataset"], e.get("test", "*"))] = e.get("reason", "")
    return out


def unfloored(run: ScoreRun | dict[str, Any], baselines: dict[str, Any]) -> list[tuple[str, str, str]]:
    """The scored (identifier, dataset, test) of ``run`` that have no floor in its mode and are not listed under
    ``dropped``: rows that no floor measured at the same budget judges. :func:`check` counts each as a failure (the
    regression check must cover every pair it scores); a run at another budget than the check's (the main job)
    reports them as not compared instead, and checks the others."""
    data = run.to_dict() if isinstance(run, ScoreRun) else run
    mode = data["mode"]
    floors = baselines.get("modes", {}).get(mode, {})
    dropped = dropped_pairs(baselines, mode)
    out = []
    for r in data["rows"]:
        key = (r["identifier"], r["dataset"], r["test"])
        if key in dropped or key[:2] + ("*",) in dropped:
            continue
        if floors.get(key[0], {}).get(key[1], {}).get(key[2]) is None:
            out.append(key)
    return out


def check(run: ScoreRun | dict[str, Any], baselines: dict[str, Any] | None = None) -> list[str]:
    """Every regression of ``run`` against ``baselines``: one line per failing pair (empty list = pass).

    A pair fails when its free-run RMSE is above its floor, it diverged or failed to run, it was scored but has no
    floor (unless listed under ``dropped`` with a reason), or a floor of the run's identifiers × datasets was not
    scored; a floor naming an identifier or dataset that does not exist fails too. Then the rules
    (:func:`check_rules`)."""
    from benchmarks.datasets import dataset_names
    from sysid.registry import IDENTIFIERS

    data = run.to_dict() if isinstance(run, ScoreRun) else run
    base = baselines if baselines is not None else load_baselines()
    mode = data["mode"]
    floors = base.get("modes", {}).get(mode, {})
    dropped = dropped_pairs(base, mode)
    failures: list[str] = []
    by_key = {(r["identifier"], r["dataset"], r["test"]): r for r in data["rows"]}
    # 1. per-pair ceilings on free-run RMSE
    for (ident, dname, test), r in by_key.items():
        if (ident, dname, test) in dropped or (ident, dname, "*") in dropped:
            continue
        floor = floors.get(ident, {}).get(dname, {}).get(test)
        if floor is None:
            failures.append(
                f"{ident} on {dname}/{test}: no {mode} floor in the baselines (measure one with "
                f"`score{' --quick' if mode == 'quick' else ''} --update-baselines`, or list the pair under "
                "'dropped' with the reason)"
            )
            continue
        rmse = (r.get("free_run") or {}).get("rmse")
        lim = floor["max_rmse"]
        if r.get("status") == "error":
            failures.append(
                f"{ident} on {dname}/{test}: failed to run ({r.get('message', '')}); "
                f"floor is free-run RMSE <= {lim:.4g}"
            )
        elif not _finite(rmse):
            failures.append(
                f"{ident} on {dname}/{test}: free run diverged or not finite; floor is free-run RMSE <= {lim:.4g}"
            )
        elif rmse > lim:
            failures.append(
                f"{ident} on {dname}/{test}: free-run RMSE {rmse:.4g} {r.get('units', '')} > floor {lim:.4g} "
                f"(baseline measured {floor.get('measured', float('nan')):.4g})"
            )
    # 2. floors that name nothing that exists, or that the run should have scored and did not
    sel = data.get("selection") or {}
    sel_i, sel_d = set(sel.get("identifiers", [])), set(sel.get("datasets", []))
    known_d = set(dataset_names())
    skipped = {(s.get("identifier"), s.get("dataset")): s.get("reason", "") for s in data.get("skipped", [])}
    for ident, dsets in floors.items():
        if ident not in IDENTIFIERS:
            failures.append(f"floor for identifier {ident!r}: no such identifier (valid: {', '.join(IDENTIFIERS)})")
            continue
        for dname, tests in dsets.items():
            if dname not in known_d:
                failures.append(f"floor for {ident} on dataset {dname!r}: no such dataset")
                continue
            if ident not in sel_i or dname not in sel_d:
                continue
            for test in tests:
                if (ident, dname, test) not in by_key:
                    why = skipped.get((ident, dname)) or skipped.get((None, dname)) or skipped.get((ident, None))
                    failures.append(
                        f"{ident} on {dname}/{test}: has a floor but was not scored"
                        + (f" (skipped: {why})" if why else "")
                    )
    return failures + check_rules(data, base)


VERSIONED = ("numpy", "scipy", "torch")  # the packages whose kernels and algorithms the floors were measured with


def version_mismatch(run: ScoreRun | dict[str, Any], baselines: dict[str, Any]) -> str | None:
    """One line naming the packages whose running version differs from the one the mode's latest floors were
    measured with (``provenance[mode][-1].versions``), or None. A mismatch does not fail the check: the floors
    may still hold, but a pair below its floor may then be the new version's doing (requirements.lock)."""
    data = run.to_dict() if isinstance(run, ScoreRun) else run
    updates = (baselines.get("provenance") or {}).get(data["mode"]) or []
    measured = (updates[-1].get("versions") or {}) if updates else {}
    running = (data.get("environment") or {}).get("versions") or {}
    diff = [
        f"{k} {running.get(k)} (floors: {measured[k]})"
        for k in VERSIONED
        if k in measured and running.get(k) != measured[k]
    ]
    if not diff:
        return None
    return (
        "score --check: warning: running versions differ from those the floors were measured with: "
        + ", ".join(diff)
        + "; install requirements.lock (make install) to compare like with like"
    )


def check_rules(run: ScoreRun | dict[str, Any], baselines: dict[str, Any]) -> list[str]:
    """The failures of ``run`` against the baselines' rules alone (beats the linear baseline, beats a value)."""
    data = run.to_dict() if isinstance(run, ScoreRun) else run
    by_key = {(r["identifier"], r["dataset"], r["test"]): r for r in data["rows"]}
    return [f for rule in baselines.get("rules", []) for f in _check_rule(rule, by_key, data.get("mode", ""))]


def _check_rule(rule: dict[str, Any], by_key: dict[tuple[str, str, str], dict[str, Any]], mode: str = "") -> list[str]:
    """Failures of one rule. A rule takes no exemptions: a pair that does not meet it is fixed, or not scored with
    the reason in the scoring settings (``only_datasets`` of ``benchmarks/settings/full.toml`` / ``quick.toml``),
    so that a user's default is never a model the check knows to be worse than linear."""
    out = []
    kind = rule["rule"]
    if "exemptions" in rule:
        raise ConfigError(
            f"baselines: rule {kind!r} lists exemptions; a rule takes none: fix the pair, or leave it out of the "
            "scoring with the reason (only_datasets in benchmarks/settings/full.toml or quick.toml)"
        )

    if kind == "beats_linear":
        linear = rule.get("linear", "arx")
        datasets = set(rule.get("datasets", []))
        for (ident, dname, test), r in by_key.items():
            if ident in LINEAR_IDENTIFIERS or dname not in datasets:
                continue
            if r.get("status") == "error":
                continue  # reported by the floors when a floor exists
            rmse = (r.get("free_run") or {}).get("rmse")
            lin = by_key.get((linear, dname, test))
            lin_rmse = (lin or {}).get("free_run", {}).get("rmse") if lin else None
            bla = (r.get("references") or {}).get("linear_baseline", {}).get("value")
            if _finite(lin_rmse) and not (_finite(rmse) and rmse < lin_rmse):
                out.append(
                    f"{ident} on {dname}/{test}: free-run RMSE {_fmt(rmse)} does not beat the linear baseline "
                    f"({linear} in this run: {_fmt(lin_rmse)})"
                )
            if _finite(bla) and not (_finite(rmse) and rmse < bla):
                out.append(
                    f"{ident} on {dname}/{test}: free-run RMSE {_fmt(rmse)} does not beat the published "
                    f"linear baseline (BLA {_fmt(bla)})"
                )
    elif kind == "beats_value":
        ident, dname = rule["identifier"], rule["dataset"]
        for test, value in rule["tests"].items():
            row = by_key.get((ident, dname, test))
            if row is None:
                continue
            rmse = (row.get("free_run") or {}).get("rmse")
            if not (_finite(rmse) and rmse < value):
                out.append(
                    f"{ident} on {dname}/{test}: free-run RMSE {_fmt(rmse)} "
                    f"does not beat {rule.get('what', 'the reference')} "
                    f"({_fmt(value)})"
                )
    else:
        raise ConfigError(f"baselines: unknown rule {kind!r}")
    return out


# Margins of the floors over the worst measured value (see :func:`make_floors`).
DEFAULT_MARGIN = 0.15
SEEDED_MARGIN = 0.5


def make_floors(
    runs: ScoreRun | dict[str, Any] | list,
    margin: float = DEFAULT_MARGIN,
    previous: dict[str, Any] | None = None,
    seeded_margin: float = SEEDED_MARGIN,
) -> dict[str, Any]:
    """Baselines from one or more measured runs of the same mode (e.g. one per CPU kernel set × BLAS threads).

    Per pair: ``measured`` = the worst (largest) free-run RMSE over the runs, ``measured_min`` the best, and the
    ceiling ``max_rmse`` = measured × (1 + margin). Rows scored as a median over training seeds (a new CPU redraws
    them, as a new seed would) get ``max(measured × (1 + seeded_margin), worst single seed × (1 + margin))``, the
    single seeds taken from every run, including quick runs over extra seeds (``score --quick --seeds 5-19``; those
    add draws, not medians). A pair that diverged or failed in any run or seed cannot get a stable floor: it goes
    to ``dropped`` with the reason. Pairs of the mode that the
    runs did not score keep their previous floors; rules and other modes are kept. The mode's ``provenance``
    gains one entry per update saying how its floors were measured (pairs, environments of the runs, seeds,
    margins, date).
    """
    import datetime

    runs = [runs] if isinstance(runs, (ScoreRun, dict)) else list(runs)
    datas = [r.to_dict() if isinstance(r, ScoreRun) else r for r in runs]
    modes = {d["mode"] for d in datas}
    if len(modes) != 1:
        raise ConfigError(f"make_floors: runs of different modes {sorted(modes)}; give runs of one mode")
    mode = modes.pop()
    for m in (margin, seeded_margin):
        if not (_finite(m) and m >= 0):
            raise ConfigError(f"margin must be a finite number >= 0, got {m!r}")
    base: dict[str, Any] = (
        json.loads(json.dumps(previous)) if previous else {"format": BASELINES_FORMAT, "modes": {}, "rules": []}
    )
    base["format"] = BASELINES_FORMAT
    values: dict[tuple[str, str, str], list[tuple[dict[str, Any], float | None]]] = {}
    draws: dict[tuple[str, str, str], list[float | None]] = {}  # single-seed free-run RMSEs of seeded rows
    for d in datas:
        for r in d["rows"]:
            key = (r["identifier"], r["dataset"], r["test"])
            seeds = r.get("seeds")
            if isinstance(seeds, list) and seeds:  # a seeded row ("deterministic" when fitted once)
                draws.setdefault(key, []).extend(r.get("free_run_rmse_by_seed") or [None])
                if mode == "quick" and list(seeds) != list(QUICK_SEEDS):
                    continue  # a run over extra seeds: only its single-seed draws count
            rmse = (r.get("free_run") or {}).get("rmse")
            ok = r.get("status") == "ok" and _finite(rmse)
            values.setdefault(key, []).append((r, rmse if ok else None))
    floors = base.setdefault("modes", {}).setdefault(mode, {})
    dropped = [
        e
        for e in base.get("dropped", {}).get(mode, [])
        if (e["identifier"], e["dataset"], e.get("test", "*")) not in values
    ]
    for (ident, dname, test), vals in values.items():
        rows = [r for r, _ in vals]
        singles = draws.get((ident, dname, test), [])
        if any(v is None for _, v in vals) or any(x is None or not _finite(x) for x in singles):
            bad = sum(v is None for _, v in vals) + sum(x is None or not _finite(x) for x in singles)
            dropped.append(
                {
                    "identifier": ident,
                    "dataset": dname,
                    "test": test,
                    "reason": f"diverged or failed in {bad} of the measured runs/seeds: no stable floor",
                }
            )
            floors.get(ident, {}).get(dname, {}).pop(test, None)
            continue
        rmses = [v for _, v in vals if v is not None]  # every one (a None was dropped above)
        seed_rmses = [x for x in singles if x is not None]
        worst, best = max(rmses), min(rmses)
        ceiling = worst * (1.0 + margin)
        if singles:  # scored as a median over seeds: a new CPU redraws the seeds
            ceiling = max(worst * (1.0 + seeded_margin), max(seed_rmses) * (1.0 + margin))
        floor = {
            "max_rmse": float(f"{ceiling:.4g}"),
            "measured": float(f"{worst:.6g}"),
            "units": rows[0].get("units", ""),
            "r2_measured": float(f"{min(r['free_run']['r2'] for r in rows):.6g}"),
        }
        if len(vals) > 1:
            floor.update(measured_min=float(f"{best:.6g}"), runs=len(vals))
        if singles:
            floor.update(
                seeds=rows[0]["seeds"],
                worst_single_seed=float(f"{max(seed_rmses):.6g}"),
                single_seed_draws=len(singles),
            )
        floors.setdefault(ident, {}).setdefault(dname, {})[test] = floor
    base.setdefault("dropped", {})[mode] = sorted(
        dropped, key=lambda e: (e["identifier"], e["dataset"], e.get("test", "*"))
    )
    envs = [d.get("environment") or {} for d in datas]
    updates = base.setdefault("provenance", {}).setdefault(mode, [])
    updates.append(
        {
            "date": datetime.date.today().isoformat(),
            "identifiers": sorted({k[0] for k in values}),
            "datasets": sorted({k[1] for k in values}),
            "how": (
                "max_rmse = worst free-run RMSE over the runs x (1 + margin); seeded identifiers scored as the median "
                f"over training seeds {list(QUICK_SEEDS) if mode == 'quick' else [0]} in each run, their max_rmse = "
                "max(worst median x (1 + seeded_margin), worst single seed of all runs x (1 + margin))"
            ),
            "margin": margin,
            "seeded_margin": seeded_margin,
            "runs": [
                {
                    k: e.get(k)
                    for k in (
                        "cpu",
                        "ATEN_CPU_CAPABILITY",
                        "torch_cpu_capability",
                        "OPENBLAS_NUM_THREADS",
                        "OPENBLAS_CORETYPE",
                        "blas_kernels",
                    )
                }
                for e in envs
            ],
            "versions": envs[0].get("versions", {}) if envs else {},
        }
    )
    return base
