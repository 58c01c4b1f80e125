"""``piezotwin run [--quick] [--report DIR]``: the main job (what ``make run`` starts).

Runs every stage of the project that is built, in order, and says what it did, how long it took and what it
skipped or left to other commands (``piezotwin records`` for the full-budget records). The stages live in
:mod:`benchmarks.mainjob`.
"""

from __future__ import annotations

import argparse


def register(sub) -> None:
    p = sub.add_parser("run", help="the main job: generate datasets, identify, score, diagnose, write the report")
    p.add_argument("--quick", action="store_true", help="one twin and one lab dataset scored (about 2 minutes)")
    p.add_argument("--report", default="report", metavar="DIR", help="report folder (default report/)")
    p.add_argument("--json", action="store_true", help="print the stage summary as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from benchmarks.mainjob import run_main_job

    summary = run_main_job(
        report_dir=args.report, quick=args.quick, verbose=not (args.json or getattr(args, "quiet", False))
    )
    if args.json:
        from benchmarks.cli.common import emit_json

        emit_json(summary)
    else:
        failed = [s["stage"] for s in summary["stages"] if s["status"] == "failed"]
        below = f"  ({summary['below_floor']} rows below floor)" if summary.get("below_floor") else ""
        print(f"report -> {summary['report']}" + below + (f"  (failed stages: {', '.join(failed)})" if failed else ""))
    return 0 if all(s["status"] != "failed" for s in summary["stages"]) else 1
