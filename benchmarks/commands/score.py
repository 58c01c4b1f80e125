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

from benchmarks.execution import add_execution_args, executor_from_args


def _names(text: str | None) -> list[str] | None:
    if text is None:
        return None
    names = [s.strip() for s in text.split(",") if s.strip()]
    return names or None


def register(sub) -> None:
    p = sub.add_parser("score", help="score identifiers x datasets against references and accuracy baselines")
    p.add_argument("--identifiers", metavar="A,B", help="comma-separated identifier ids (default: every available one)")
    p.add_argument("--datasets", metavar="X,Y", help="comma-separated dataset ids (default: every available one; "
                                                     "--quick: the quick set)")
    p.add_argument("--quick", action="store_true", help="reduced settings and data budgets (the CI check)")
    p.add_argument("--check", action="store_true", help="exit 1 if any pair falls below its floor in benchmarks/baselines.json")
    p.add_argument("--baselines", metavar="FILE", help="baselines file (default benchmarks/baselines.json)")
    p.add_argument("--update-baselines", action="store_true", help="write floors measured in this run to the baselines file")
    p.add_argument("--margin", type=float, default=0.15, help="margin of --update-baselines (default 0.15 = 15 %%)")
    p.add_argument("--no-sysidentpy", action="store_true", help="do not run SysIdentPy's FROLS beside the rows")
    p.add_argument("--report", metavar="DIR", help="write score.json, score.md and figures to DIR")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    add_execution_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from benchmarks import scoring
    from benchmarks.commands.common import emit_json
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
    if args.margin < 0:
        raise ConfigError(f"--margin must be >= 0, got {args.margin}")
    baselines = scoring.load_baselines(args.baselines)
    quiet = args.json
    with executor_from_args(args) as ex:
        res = scoring.score(idents, dsets, quick=args.quick, sysidentpy=not args.no_sysidentpy, progress=not quiet,
                            log=None if quiet else (lambda s: print(s, flush=True)), executor=ex)
    out = scoring._clean(res.to_dict())
    if args.check:
        failures = scoring.check(res, baselines)
        out["check"] = {"passed": not failures, "failures": failures}
    if args.report:
        paths = scoring.write_report(res, args.report)
        out["report"] = {k: str(v) for k, v in paths.items()}
    if args.update_baselines:
        import json
        from pathlib import Path

        new = scoring.make_floors(res, margin=args.margin, previous=baselines)
        path = Path(args.baselines) if args.baselines else scoring.BASELINES_PATH
        path.write_text(json.dumps(new, indent=2) + "\n")
        out["baselines_written"] = str(path)
    if args.json:
        emit_json(out)
    else:
        for s in res.skipped:
            what = " on ".join(x for x in (s.get("identifier"), s.get("dataset")) if x)
            print(f"skipped {what}: {s['reason']}")
        for s in res.sysidentpy:
            if s.get("status") == "ok":
                print(f"{'sysidentpy':<12} {s['dataset']:<20} {s['test']:<22} free-run RMSE {scoring._fmt(s['free_run']['rmse'])} "
                      f"(R2 {scoring._fmt(s['free_run']['r2'])})  fit {s['fit_seconds']:.2f} s  {s['n_parameters']} terms")
            else:
                print(f"{'sysidentpy':<12} {s['dataset']:<20} {s['test']:<22} skipped: {s.get('reason', '')}")
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
