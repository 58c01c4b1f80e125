"""``piezotwin search IDENTIFIER --est FILE (--val FILE | --folds K) --grid SPEC [--repeats R] [--json]``.

Structure sweep with repeated runs (dissertation Tables 4.2, 5.4–5.6, Fig. 5.13) on Optuna; see
:mod:`sysid.search`. SPEC: ``KEY=V1,V2,...`` items separated by ``;`` — identifier options as for
``identify --set``; list values with dashes (``hidden=25-25,25-25-25-25``); integer ranges ``a..b``; ``lags``
sets ny and nu together. Example::

    piezotwin search narx-mlp --est est.npz --val val.npz \\
        --grid "lags=5,10;hidden=25-25,25-25-25-25;activation=relu,tanh" --repeats 5 --set epochs=20

Storage: ``--storage FILE.db`` (SQLite, default ``STUDY.db`` in the current folder) or an Optuna URL such as
``postgresql://user:pw@host/db`` shared by workers on several machines (run the same command on each).
Re-running the same command resumes an interrupted sweep; it exits 0 only when the study holds the requested
number of finished configurations, else 1 with a line saying how many are missing. ``--workers N`` runs N
local search processes; ``--scheduler ADDRESS`` (or ``PIEZOTWIN_SCHEDULER``) runs each configuration's
repeats as tasks on a Dask cluster (:mod:`benchmarks.execution`).
"""

from __future__ import annotations

import argparse
import sys

from benchmarks.cli.common import COUNT, SEED, add_data_args, add_set_arg, emit_json, number, read_data, same_fs
from benchmarks.execution import add_execution_args, make_executor
from sysid.config import parse_assignments


def register(sub) -> None:
    p = sub.add_parser(
        "search",
        help="structure sweep with repeated runs (grid / random / TPE, Optuna storage)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="SPEC: KEY=V1,V2,... items separated by ';'. Keys are the identifier's options (as for\n"
        "identify --set); list values use dashes (hidden=25-25,25-25-25-25 is two choices);\n"
        "a..b is every integer from a to b; 'lags' sets ny and nu together (n_enc for rnn).\n"
        "Example: --grid 'lags=5,10;hidden=25-25,25-25-25-25;activation=relu,tanh'\n"
        "Re-running the same command resumes the sweep stored in --storage/--study.",
    )
    p.add_argument("identifier", help="identifier id (narx-mlp, narx-mlp-sim, rnn, narx-poly, ...)")
    p.add_argument("--est", required=True, action="append", metavar="FILE", help="estimation record; may repeat")
    p.add_argument("--val", metavar="FILE", help="validation record (or give --folds)")
    p.add_argument(
        "--folds",
        type=COUNT,
        metavar="K",
        help="instead of --val: blocked K-fold cross-validation on the one --est record (K >= 2; each run "
        "fitted K times, each contiguous K-th held out in turn; the scores are the folds' means)",
    )
    p.add_argument(
        "--grid",
        required=True,
        metavar="SPEC",
        help="choices, e.g. 'lags=5,10;hidden=25-25,25-25-25-25;activation=relu,tanh'",
    )
    p.add_argument(
        "--repeats", type=COUNT, default=1, metavar="R", help="runs per configuration (seeds seed..seed+R-1)"
    )
    p.add_argument("--seed", type=SEED, default=0, help="first seed (default 0)")
    add_set_arg(p, "options fixed for every run (e.g. epochs=20)")
    p.add_argument("--sampler", choices=("grid", "random", "tpe"), default="grid")
    p.add_argument("--trials", type=COUNT, metavar="N", help="configurations to evaluate (default: the whole grid)")
    p.add_argument("--storage", metavar="URL|FILE", help="Optuna storage: SQLite file (default STUDY.db) or URL")
    p.add_argument("--study", default="piezotwin-search", help="study name inside the storage")
    p.add_argument(
        "--workers",
        type=number(1, 256, integer=True),
        default=1,
        help="local worker processes sharing the storage (each runs whole configurations)",
    )
    p.add_argument("--export", metavar="FILE.jsonl", help="write one JSON line per run")
    p.add_argument("--plot", metavar="FILE.png", help="R² distribution of the best configuration (Fig. 5.13 analogue)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_data_args(p)
    add_execution_args(p, workers=False)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=run)


def _fmt(v) -> str:
    return "   nan" if v is None else f"{v:.4f}"


def run(args: argparse.Namespace) -> int:
    from sysid.errors import ConfigError
    from sysid.search import (
        SweepSpec,
        _open_storage,
        collect,
        export_jsonl,
        parse_grid,
        plot_r2_distribution,
        run_sweep,
        storage_url,
    )
    from sysid.search.storage_check import check_storage, init_sqlite

    if args.workers < 1:
        raise ConfigError(f"--workers must be ≥ 1, got {args.workers}")
    if (args.val is None) == (args.folds is None):
        raise ConfigError("give exactly one of --val FILE and --folds K")
    if args.folds is not None and len(args.est) != 1:
        raise ConfigError(f"--folds cross-validates one estimation record; got {len(args.est)} --est files")
    check_storage(args.storage, args.study)  # before any work: a bad --storage leaves nothing behind
    est = [read_data(args, f) for f in args.est]
    val = None if args.val is None else read_data(args, args.val)
    same_fs(est + ([] if val is None else [val]))
    spec = SweepSpec(
        identifier=args.identifier,
        grid=parse_grid(args.grid, args.identifier),
        repeats=args.repeats,
        seed=args.seed,
        fixed=parse_assignments(args.set_),
        sampler=args.sampler,
        folds=args.folds or 0,
    )
    init_sqlite(storage_url(args.storage, args.study), _open_storage)  # new SQLite store: created under a lock
    with make_executor(scheduler=args.scheduler) as ex:
        if ex.kind == "dask" and args.workers > 1:
            raise ConfigError(
                "--workers N runs N local search processes; with --scheduler the repeats run on the "
                "Dask workers: give one of them"
            )
        est_h = ex.share(est if len(est) > 1 else est[0]) if ex.kind == "dask" else (est if len(est) > 1 else est[0])
        val_h = ex.share(val) if ex.kind == "dask" and val is not None else val
        summary = run_sweep(
            spec,
            est_h,
            val_h,
            storage=args.storage,
            study=args.study,
            trials=args.trials,
            workers=args.workers,
            progress=not (args.no_progress or getattr(args, "quiet", False)),
            executor=ex if ex.kind == "dask" else None,
        )
    url = storage_url(args.storage, args.study)
    summary.update(
        {
            "identifier": args.identifier,
            "study": args.study,
            "storage": url,
            "sampler": args.sampler,
            "repeats": args.repeats,
            "grid": spec.grid,
            "validated_on": f"blocked {args.folds}-fold cross-validation on the estimation record"
            if args.folds
            else "the --val record",
        }
    )
    runs = collect(url, args.study) if args.export or args.plot else []
    if args.export:
        summary["runs_file"] = str(export_jsonl(runs, args.export))
    if args.plot and summary["best"] is not None:
        summary["plot"] = str(plot_r2_distribution(runs, summary["best"]["config_key"], args.plot))
    missing = summary["missing"]
    if missing:  # stderr, so that --json output stays one document
        print(
            f"search: {missing} of {summary['requested']} requested configurations did not complete "
            f"({summary['complete']} complete in study {args.study}); rerun the same command to resume",
            file=sys.stderr,
        )
    if args.json:
        emit_json(summary)
        return 1 if missing else 0
    print(
        f"{args.identifier}: {summary['n_configs']} configurations, {summary['n_runs']} runs  "
        f"(storage {url}, study {args.study})"
    )
    if args.folds:
        print(f"  val = blocked {args.folds}-fold cross-validation on the estimation record: means over the folds")
    print(
        f"  {'configuration':<44} {'params':>7}  {'R2 OSA est':>10} {'R2 FRS est':>17} "
        f"{'R2 OSA val':>10} {'R2 FRS val':>17}"
    )
    for c in summary["configs"]:
        print(
            f"  {c['config_key']:<44} {c['n_parameters']:>7}  {_fmt(c['r2_est_osa_mean']):>10} "
            f"{_fmt(c['r2_est_frs_mean'])} ± {_fmt(c['r2_est_frs_sd'])} {_fmt(c['r2_val_osa_mean']):>10} "
            f"{_fmt(c['r2_val_frs_mean'])} ± {_fmt(c['r2_val_frs_sd'])}"
            + (f"  ({c['diverged_val_frs']} of {c['runs']} diverged)" if c.get("diverged_val_frs") else "")
        )
    if summary["best_runs"]:
        print("  runs of the best configuration (Table 5.6 analogue):")
        for r in summary["best_runs"]:
            print(
                f"    seed {r['seed']:>4}: OSA est {_fmt(r['r2_est_osa'])}  FRS est {_fmt(r['r2_est_frs'])}  "
                f"OSA val {_fmt(r['r2_val_osa'])}  FRS val {_fmt(r['r2_val_frs'])}"
            )
    for key in ("runs_file", "plot"):
        if key in summary:
            print(f"  {key} -> {summary[key]}")
    return 1 if missing else 0
