"""``piezotwin score [--identifiers a,b] [--datasets x,y] [--quick] [--check] [--report DIR] [--json]``.

Scores identifiers × datasets (test RMSE, NRMSE, R² one-step and free-run, fit time, parameter count) beside
the published reference numbers and SysIdentPy's FROLS on the same split. ``--check`` compares with
``benchmarks/baselines.json`` and exits 1 naming every pair below its floor. ``--update-baselines`` writes
new floors from this run (measured × (1 + margin)) — a deliberate step, to be committed.
``--workers N`` / ``--scheduler ADDRESS`` run the pairs on Dask (:mod:`benchmarks.execution`).
"""

from __future__ import annotations

import argparse
import sys

from benchmarks.cli.common import number, seed_range
from benchmarks.execution import add_execution_args, executor_from_args


def _names(text: str | None) -> list[str] | None:
    if text is None:
        return None
    names = [s.strip() for s in text.split(",") if s.strip()]
    return names or None


def register(sub) -> None:
    p = sub.add_parser("score", help="score identifiers x datasets against references and accuracy baselines")
    p.add_argument("--identifiers", metavar="A,B", help="comma-separated identifier ids (default: every available one)")
    p.add_argument(
        "--datasets",
        metavar="X,Y",
        help="comma-separated dataset ids (default: every available one; --quick: the quick set)",
    )
    p.add_argument("--quick", action="store_true", help="reduced settings and data budgets (the CI check)")
    p.add_argument(
        "--check", action="store_true", help="exit 1 if any pair falls below its floor in benchmarks/baselines.json"
    )
    p.add_argument("--baselines", metavar="FILE", help="baselines file (default benchmarks/baselines.json)")
    p.add_argument(
        "--update-baselines", action="store_true", help="write floors measured in this run to the baselines file"
    )
    p.add_argument(
        "--margin", type=number(0, 10), default=0.15, help="margin of --update-baselines (default 0.15 = 15 %%)"
    )
    p.add_argument(
        "--seeded-margin",
        type=number(0, 10),
        default=0.5,
        help="margin of --update-baselines for identifiers scored over several training seeds (default 0.5)",
    )
    p.add_argument(
        "--seeds",
        metavar="A-B",
        type=seed_range,
        help="training seeds of the seeded (neural) identifiers, each test scored by the median seed and "
        "listed per seed with mean and SD (default: 0-4 with --quick, the identifier's own seed "
        "without); deterministic identifiers are fitted once and say so; quick runs over other seeds "
        "add single-seed draws to --update-baselines --from-runs",
    )
    p.add_argument(
        "--from-runs",
        nargs="+",
        metavar="RUN.json",
        help="with --update-baselines: set floors from these saved `score --json` runs (e.g. one per CPU "
        "kernel set and BLAS thread count; the worst value of each pair counts) instead of scoring now",
    )
    p.add_argument("--no-sysidentpy", action="store_true", help="do not run SysIdentPy's FROLS beside the rows")
    p.add_argument("--report", metavar="DIR", help="write score.json, score.md and figures to DIR")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    add_execution_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from benchmarks import scoring
    from benchmarks.cli.common import emit_json
    from benchmarks.datasets import dataset_names
    from sysid.errors import ConfigError
    from sysid.registry import IDENTIFIERS

    idents, dsets = _names(args.identifiers), _names(args.datasets)
    for i in idents or []:
        if i not in IDENTIFIERS:
            raise ConfigError(f"unknown identifier {i!r}; valid: {', '.join(IDENTIFIERS)}")
    for d in dsets or []:
        if d not in dataset_names():
            raise ConfigError(f"unknown dataset {d!r}; valid: {', '.join(dataset_names())}")
    from pathlib import Path

    bpath = Path(args.baselines) if args.baselines else scoring.BASELINES_PATH
    # --check needs the floors; --update-baselines may start a new file
    baselines = scoring.load_baselines(bpath) if args.check or bpath.exists() else None
    if args.seeds is not None and args.check:
        raise ConfigError("--seeds changes what the floors measure: use it to measure (--json), not with --check")
    if args.from_runs:
        if not args.update_baselines or args.check:
            raise ConfigError("--from-runs goes with --update-baselines (and without --check)")
        return _floors_from_runs(args, bpath, baselines)
    quiet = args.json
    with executor_from_args(args) as ex:
        res = scoring.score(
            idents,
            dsets,
            quick=args.quick,
            sysidentpy=not args.no_sysidentpy,
            progress=not (quiet or getattr(args, "quiet", False)),
            log=None if quiet else (lambda s: print(s, flush=True)),
            seeds=args.seeds,
            executor=ex,
        )
    out = scoring._clean(res.to_dict())
    if args.check:
        failures = scoring.check(res, baselines)
        out["check"] = {"passed": not failures, "failures": failures}
        warning = scoring.version_mismatch(res, baselines or {})
        if warning:
            out["check"]["version_warning"] = warning
            print(warning, file=sys.stderr)
    if args.report:
        paths = scoring.write_report(res, args.report)
        out["report"] = {k: str(v) for k, v in paths.items()}
    if args.update_baselines:
        new = scoring.make_floors(res, margin=args.margin, previous=baselines, seeded_margin=args.seeded_margin)
        _write_json(bpath, new)
        out["baselines_written"] = str(bpath)
    if args.json:
        emit_json(out)
    else:
        for s in res.skipped:
            what = " on ".join(x for x in (s.get("identifier"), s.get("dataset")) if x)
            print(f"skipped {what}: {s['reason']}")
        for row in res.sysidentpy:
            if row.get("status") == "ok":
                print(
                    f"{'sysidentpy':<12} {row['dataset']:<20} {row['test']:<22} "
                    f"free-run RMSE {scoring._fmt(row['free_run']['rmse'])} "
                    f"(R2 {scoring._fmt(row['free_run']['r2'])})  fit {row['fit_seconds']:.2f} s  "
                    f"{row['n_parameters']} terms"
                )
            else:
                print(f"{'sysidentpy':<12} {row['dataset']:<20} {row['test']:<22} skipped: {row.get('reason', '')}")
        if args.report:
            print(f"report -> {args.report}/score.md")
        if args.update_baselines:
            print(f"baselines -> {out['baselines_written']}")
        print(f"{len(res.rows)} rows in {res.seconds:.1f} s")
    if args.check:
        failures = out["check"]["failures"]
        if failures:
            print(f"score --check: {len(failures)} pair(s) below their floor:", file=sys.stderr)
            for f in failures:
                print(f"  {f}", file=sys.stderr)
            return 1
        if not args.json:
            print("score --check: every pair meets its floor")
    return 0


def _write_json(path, obj) -> None:
    import json

    from sysid.data.safeio import atomic_write_text

    atomic_write_text(path, json.dumps(obj, indent=2) + "\n")


def _floors_from_runs(args: argparse.Namespace, bpath, baselines) -> int:
    """``--update-baselines --from-runs RUN.json ...``: floors from saved runs (the worst value of each pair)."""
    import json
    from pathlib import Path

    from benchmarks import scoring
    from sysid.errors import ConfigError

    runs = []
    for name in args.from_runs:
        try:
            data = json.loads(Path(name).read_text())
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ConfigError(f"{name}: cannot read a score run ({exc})") from None
        if (
            not isinstance(data, dict)
            or data.get("format") != "piezotwin-score/1"
            or not isinstance(data.get("rows"), list)
        ):
            raise ConfigError(f"{name}: not a `piezotwin score --json` run")
        runs.append(data)
    new = scoring.make_floors(runs, margin=args.margin, previous=baselines, seeded_margin=args.seeded_margin)
    _write_json(bpath, new)
    mode = runs[0]["mode"]
    n = sum(len(t) for d in new["modes"][mode].values() for t in d.values())
    dropped = new.get("dropped", {}).get(mode, [])
    print(f"baselines -> {bpath}: {n} {mode} floors from {len(runs)} runs, {len(dropped)} pairs dropped")
    for e in dropped:
        print(f"  dropped {e['identifier']} on {e['dataset']}/{e.get('test', '*')}: {e['reason']}")
    return 0
