"""``piezotwin thesis [--quick | --tier T] [--rows ID,...] [--repeats N] [--workers N | --scheduler ADDR] [--store]
[--render-only] [--json]``: the dissertation's tables and figures measured on the twins.

Every row (``table-4.2/4x25``, ``table-5.2/narmax-4-5-8-rho1e-06``, ``fig-3.4/peak`` …; a table name selects all its
rows) runs its protocol at the tier's budget and is printed beside the dissertation's value; ``--store`` merges
the rows into ``docs/dissertation/rows.json`` and renders ``docs/dissertation.md`` from every stored row;
``--render-only`` fits nothing and only renders.
"""

from __future__ import annotations

import argparse

from benchmarks.cli.common import COUNT
from benchmarks.execution import add_execution_args


def register(sub) -> None:
    p = sub.add_parser("thesis", help="the dissertation's tables and figures on the twins -> docs/dissertation.md")
    p.add_argument("--quick", action="store_true", help="every row at a tiny budget (1 epoch, 1 run, short records)")
    p.add_argument(
        "--tier",
        choices=("quick", "middle", "full"),
        default=None,
        help="budget: middle (default; 100/75 epochs, 2-3 runs, 20 runs for Fig. 5.13) or full (the "
        "dissertation's: 5 runs, 75 for Fig. 5.13)",
    )
    p.add_argument(
        "--rows",
        "--only",
        metavar="ID,...",
        help="rows or tables to measure, e.g. table-4.2,fig-3.4/peak (default: every row)",
    )
    p.add_argument("--repeats", type=COUNT, metavar="N", help="runs of every repeated experiment (overrides the tier)")
    p.add_argument(
        "--store", action="store_true", help="merge the measured rows into the stored rows and render the page"
    )
    p.add_argument("--render-only", action="store_true", help="fit nothing: render the page from the stored rows")
    p.add_argument("--stored", metavar="FILE", help="stored rows (default docs/dissertation/rows.json)")
    p.add_argument("--markdown", metavar="FILE", help="page to write (default docs/dissertation.md)")
    p.add_argument(
        "--grid-sample",
        metavar="N|all",
        help="also train a random sample of N of Table 5.3's architectures (2 runs, 75 epochs, thesis preset); "
        "'all': the whole grid (use --scheduler)",
    )
    p.add_argument("--grid-seed", type=int, default=0, metavar="S", help="seed of the --grid-sample draw (default 0)")
    p.add_argument("--json", action="store_true", help="print the rows as JSON")
    add_execution_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from benchmarks import thesis
    from benchmarks.cli.common import emit_json
    from benchmarks.execution import executor_from_args
    from benchmarks.thesis.grid import write as write_grid
    from benchmarks.thesis.plan import tier, with_repeats
    from benchmarks.thesis.rows import load_rows, write_rows
    from benchmarks.thesis.runner import measure, measure_grid, select_rows
    from sysid.data.safeio import check_output_path
    from sysid.errors import ConfigError

    if args.quick and args.tier not in (None, "quick"):
        raise ConfigError(f"--quick is --tier quick: give one of them, not --tier {args.tier}")
    if args.render_only and (args.rows or args.store or args.quick or args.tier or args.repeats or args.grid_sample):
        raise ConfigError(
            "--render-only renders every stored row: give it without "
            "--rows/--store/--quick/--tier/--repeats/--grid-sample"
        )
    stored = check_output_path(args.stored or thesis.ROWS_PATH)
    page = check_output_path(args.markdown or thesis.PAGE_PATH)
    quiet = args.json or getattr(args, "quiet", False)
    if args.render_only:
        rows = load_rows(stored)
        thesis.write_page(rows, page, grid=stored.parent / thesis.GRID_PATH.name)
        if args.json:
            emit_json({"rows": rows})
        elif not quiet:
            print(f"{len(rows)} stored rows -> {page}")
        return 0
    grid_n = _grid_n(args.grid_sample)
    chosen = select_rows(args.rows) if (args.rows or grid_n is False) else []
    t = tier("quick" if args.quick else (args.tier or "middle"))
    if args.repeats is not None:
        t = with_repeats(t, args.repeats)

    def line(key: str, res: dict) -> None:
        if not quiet:
            print(f"  fit {key}: {res.get('cpu_seconds', 0.0):.1f} s CPU", flush=True)

    grid = None
    with executor_from_args(args) as ex:
        rows = measure(chosen, t, executor=ex, progress=not quiet, on_task=line) if chosen else {}
        if grid_n is not False:
            grid = measure_grid(grid_n, args.grid_seed, executor=ex, progress=not quiet, on_task=line)
    if args.store:
        if rows:
            write_rows(rows, stored)
        if grid is not None:
            write_grid(grid, stored.parent / thesis.GRID_PATH.name)
        thesis.write_page(load_rows(stored), page, grid=stored.parent / thesis.GRID_PATH.name)
    if args.json:
        emit_json({"tier": t.as_dict(), "rows": rows, **({"grid": grid} if grid is not None else {})})
        return 0
    if not quiet and grid is not None:
        print(f"Table 5.3 sample: {grid['sample_size']} of {grid['grid_size']} configurations, best {grid['best']}")
    if not quiet:
        for rid, r in rows.items():
            d, p = r["dissertation"], r["project"]
            mean = "failed" if p["mean"] is None else f"{p['mean']:.4g}"
            sd = f" ± {p['sd']:.2g}" if p.get("sd") is not None else ""
            pre = r.get("preset")
            extra = ""
            if pre:
                pm = pre["project"]["mean"]
                extra = f"  | preset {'failed' if pm is None else f'{pm:.4g}'}  {pre['verdict']}"
            print(f"{rid:<34} dissertation {d['value']:.4g}  project {mean}{sd} (n={p['n']})  {r['verdict']}{extra}")
        if args.store:
            print(f"{len(rows)} rows stored -> {stored}, {page}" if rows else f"page -> {page}")
    return 0


def _grid_n(spec: str | None) -> int | None | bool:
    """``--grid-sample``: ``False`` when absent, ``None`` for ``all``, else a positive count (exit 2 otherwise)."""
    from sysid.errors import ConfigError

    if spec is None:
        return False
    if spec.strip().lower() == "all":
        return None
    try:
        n = int(spec)
    except ValueError:
        n = 0
    if n < 1:
        raise ConfigError(f"--grid-sample must be a positive count or 'all', got {spec!r}")
    return n
