"""``piezotwin bench-diagnosis [--cases N | --sample ci] [--workers N | --scheduler ADDR] [--json] [--report DIR]``:
the diagnosis benchmark (:mod:`benchmarks.diagnosis_bench`).

``--cases N`` diagnoses the cases of seeds 0 … N−1 (default: the full set of ``benchmarks/settings/
diagnosis_bench.toml``), appending a row per case to ``--results`` as it finishes (a rerun resumes: cases in the
file are not diagnosed again), then scores every row and renders docs/diagnosis-benchmark.md, its figure and
summary. ``--sample ci`` diagnoses the stratified CI sample of the settings afresh and compares it with the stored
rows of the same cases (exit 1 when a rate drops by more than its sampling error). ``--render-only`` scores and
renders the stored rows without diagnosing anything.
"""

from __future__ import annotations

import argparse
import datetime
import sys
import tempfile
import tomllib
from pathlib import Path

from benchmarks.cli.common import emit_json
from benchmarks.execution import add_execution_args, executor_from_args
from sysid.errors import ConfigError

SETTINGS = Path(__file__).resolve().parents[1] / "settings" / "diagnosis_bench.toml"


def register(sub) -> None:
    p = sub.add_parser("bench-diagnosis", help="benchmark the diagnosis on generated hidden-effect cases")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--cases", type=int, metavar="N", help="diagnose the cases of seeds 0..N-1 (default: the full set)")
    g.add_argument("--sample", choices=["ci"], help="diagnose the CI sample afresh and compare with the stored rows")
    g.add_argument("--render-only", action="store_true", help="score and render the stored rows only")
    p.add_argument("--results", metavar="FILE.jsonl", help="rows file (default docs/diagnosis-benchmark/results.jsonl)")
    p.add_argument("--report", metavar="DIR", help="write the page, figure and summary here (default docs/)")
    p.add_argument("--json", action="store_true", help="print the scores (or the CI comparison) as JSON")
    add_execution_args(p)
    p.set_defaults(func=run)


def _settings() -> dict:
    with open(SETTINGS, "rb") as fh:
        return tomllib.load(fh)


def run(args: argparse.Namespace) -> int:
    from benchmarks.diagnosis_bench import page
    from benchmarks.diagnosis_bench.calibrate import examples, held_out
    from benchmarks.diagnosis_bench.run import read_rows, run_cases
    from benchmarks.diagnosis_bench.score import score

    settings = _settings()
    results = Path(args.results) if args.results else page.DOCS_DIR / "results.jsonl"
    if args.cases is not None and args.cases < 1:
        raise ConfigError(f"--cases must be >= 1, got {args.cases}")
    if args.sample:
        return _ci(args, settings, results)
    n = args.cases or int(settings["full"]["cases"])
    seeds = list(range(n))
    if args.render_only:
        rows = [r for r in read_rows(results) if r["case"]["seed"] < n]
        if not rows:
            raise ConfigError(f"{results}: no stored rows to render")
    else:
        ex = executor_from_args(args)
        try:
            rows = run_cases(seeds, results, ex, on_row=lambda r: _say(args, r))
        finally:
            ex.close()
    scores = score(rows)
    scores["calibration_held_out"] = held_out(*examples(rows))
    docs = Path(args.report) if args.report else page.DOCS_DIR.parent
    out_dir = docs / page.DOCS_DIR.name
    meta = {
        "command": f"piezotwin bench-diagnosis --cases {n}",
        "date": datetime.date.today().isoformat(),
        "machine": page.machine(),
        "seeds": _ranges(sorted(r["case"]["seed"] for r in rows)),
        "complete": len(rows) == n,
        "results": str(results),
        "code": _codes(rows),
    }
    page.figure(rows, scores, out_dir / "figure.png")
    written = page.render(scores, meta, docs / page.PAGE.name, out_dir)
    if args.json:
        emit_json(scores)
    elif not args.quiet:
        _print(scores, written)
    return 0


def _codes(rows: list[dict]) -> list[tuple[str, int]]:
    """(commit, rows diagnosed by it), most rows first: the short hash, with its note when the tree had uncommitted
    changes; rows from before rows carried it are "earlier"."""
    from collections import Counter

    def short(code: str) -> str:
        head, _, note = code.partition(" ")
        return head[:7] + (f" {note}" if note else "")

    return Counter(short(str(r["code"])) if r.get("code") else "earlier" for r in rows).most_common()


def _ranges(seeds: list[int]) -> str:
    """``[0, 1, 2, 5, 7, 8]`` → ``"0–2, 5, 7–8"``: the seeds a page was scored on."""
    parts: list[str] = []
    for s in seeds:
        if parts and s == int(parts[-1].split("–")[-1]) + 1:
            parts[-1] = f"{parts[-1].split('–')[0]}–{s}"
        else:
            parts.append(str(s))
    return ", ".join(parts)


def _say(args: argparse.Namespace, row: dict) -> None:
    if getattr(args, "quiet", False):
        return
    c = row["case"]
    named = ", ".join(f"{x['effect']} {x['confidence']:.2f}" for x in row.get("causes", [])) or "-"
    print(
        f"[bench-diagnosis] case {c['seed']}: {c['model']} {c['mechanism'] or 'none'} -> "
        f"{row.get('verdict', 'error')} ({named}) {row.get('cpu_s', 0.0):.0f} s CPU",
        file=sys.stderr,
        flush=True,
    )


def _print(scores: dict, written: Path) -> None:
    r = scores["right_above_3dl"]
    print(f"diagnosis benchmark: {scores['cases']} cases, {scores['errors']} failed")
    if r["n"]:
        print(f"  right cause at >= 3x detection limit: {r['k']}/{r['n']} ({100 * r['rate']:.0f} %)")
    cw = scores["confident_wrong"]
    print(f"  confident wrong names: {cw['k']}/{cw['n']}")
    print(f"  page -> {written}")


def _ci(args: argparse.Namespace, settings: dict, results: Path) -> int:
    import json

    from benchmarks.diagnosis_bench.check import compare
    from benchmarks.diagnosis_bench.page import DOCS_DIR
    from benchmarks.diagnosis_bench.run import read_rows, run_cases

    seeds = [int(s) for s in settings["ci"]["seeds"]]
    stored = [r for r in read_rows(results) if r["case"]["seed"] in set(seeds)]
    if len(stored) < len(seeds):
        raise ConfigError(f"{results}: {len(seeds) - len(stored)} of the CI sample's cases are not stored")
    summary = json.loads((DOCS_DIR / "summary.json").read_text())["scores"]
    limits = summary["detection_limits"]
    full = {f"catalog:{k}": v["rate"] for k, v in summary["strata"]["family"].items() if v["rate"] is not None}
    full.update(none=summary["none_right"]["rate"] or 0.0, outside=summary["outside_unexplained"]["rate"] or 0.0)
    # the longest cases first (their stored CPU): two workers finish together instead of one waiting on a late
    # acoustic case (22 cases: 4 min 53 s in seed order, the CPU shared evenly would take 4 min)
    cpu = {r["case"]["seed"]: float(r.get("cpu_s") or 0.0) for r in stored}
    ex = executor_from_args(args)
    with tempfile.TemporaryDirectory(prefix="bench_ci_") as tmp:
        try:
            order = sorted(seeds, key=lambda s: -cpu[s])
            now = run_cases(order, Path(tmp) / "rows.jsonl", ex, on_row=lambda r: _say(args, r))
        finally:
            ex.close()
    result = compare(now, stored, limits, full)
    if args.json:
        emit_json(result)
    else:
        for g in result["groups"]:
            state = "ok" if g["passed"] else "DROPPED"
            print(
                f"  {g['group']}: {g['now']:.2f} now, {g['stored']:.2f} stored "
                f"(allowed drop {g['allowed_drop']:.2f}, {g['n']} cases) {state}"
            )
        cw = result["confident_wrong"]
        print(f"  confident wrong names: {cw['now']} now, {cw['stored']} stored {'ok' if cw['passed'] else 'MORE'}")
    return 0 if result["passed"] else 1
