"""``piezotwin records [--datasets D,E] [--render-only] [--json]``: the records table of ``docs/benchmarks.md``.

For every dataset of ``benchmarks/settings/records.toml`` (or those of ``--datasets``) scores its identifier with
the full settings over training seeds 0-2, exactly as the printed ``piezotwin score`` command does, stores the
raw result with how it was measured in ``docs/records/<dataset>.json`` (a row shown ``beside`` it in
``docs/records/<dataset>--<identifier>.json``), then renders ``docs/benchmarks.md`` and
``benchmarks/records.json`` from every stored row (the rows not measured now are kept as stored).
``--identifiers`` measures only those identifiers' rows of the chosen datasets.
``--render-only`` fits nothing and only renders.
"""

from __future__ import annotations

import argparse
import logging

from benchmarks.cli.common import seed_range
from benchmarks.execution import add_execution_args, executor_from_args


def register(sub) -> None:
    p = sub.add_parser(
        "records", help="measure the records rows and write docs/benchmarks.md and benchmarks/records.json"
    )
    p.add_argument(
        "--datasets",
        metavar="X,Y",
        help="measure only these rows of the records settings (default: every row); the others are rendered as stored",
    )
    p.add_argument(
        "--identifiers",
        metavar="X,Y",
        help="measure only the rows of these identifiers (the chosen "
        "one or those shown beside it; default: every row of "
        "the chosen datasets)",
    )
    p.add_argument(
        "--render-only", action="store_true", help="fit nothing: render the page and records.json from the stored rows"
    )
    p.add_argument(
        "--seeds",
        metavar="A-B",
        type=seed_range,
        default=None,
        help="training seeds of every measured row (default 0-2); deterministic identifiers are fitted once",
    )
    p.add_argument(
        "--settings", metavar="FILE", help="dataset -> identifier table (default benchmarks/settings/records.toml)"
    )
    p.add_argument("--stored", metavar="DIR", help="folder of the stored rows (default docs/records)")
    p.add_argument("--markdown", metavar="FILE", help="page to write (default docs/benchmarks.md)")
    p.add_argument("--records-json", metavar="FILE", help="summary to write (default benchmarks/records.json)")
    p.add_argument(
        "--in-process",
        action="store_true",
        help="measure the rows in this process, not each in a fresh one (quicker to start; a row's times "
        "then include no numba compilation that an earlier row already paid)",
    )
    p.add_argument("--json", action="store_true", help="print the records.json mapping")
    add_execution_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from benchmarks import records
    from benchmarks.cli.common import emit_json
    from benchmarks.scoring import format_row
    from sysid.data.safeio import check_output_dir, check_output_path
    from sysid.errors import ConfigError

    entries = records.load_entries(args.settings)
    stored = check_output_dir(args.stored or records.STORED_DIR)
    markdown = check_output_path(args.markdown or records.MARKDOWN_PATH)
    summary_path = check_output_path(args.records_json or records.RECORDS_JSON)
    chosen = entries
    if args.datasets is not None:
        names = [s.strip() for s in args.datasets.split(",") if s.strip()]
        known = {e.dataset: e for e in entries}
        for n in names:
            if n not in known:
                raise ConfigError(f"--datasets: {n!r} has no row in the records settings; valid: {', '.join(known)}")
        chosen = [known[n] for n in names]
    chosen = records.with_beside(chosen)
    if args.identifiers is not None:
        wanted = [s.strip() for s in args.identifiers.split(",") if s.strip()]
        valid = dict.fromkeys(e.identifier for e in chosen)
        for w in wanted:
            if w not in valid:
                raise ConfigError(f"--identifiers: {w!r} has no row in the chosen datasets; valid: {', '.join(valid)}")
        chosen = [e for e in chosen if e.identifier in wanted]
    if args.render_only and (args.datasets is not None or args.identifiers is not None):
        raise ConfigError("--render-only renders every stored row: give it without --datasets or --identifiers")
    seeds = args.seeds if args.seeds is not None else list(records.DEFAULT_SEEDS)
    records.seeds_text(seeds)
    quiet = args.json or getattr(args, "quiet", False)
    if not args.render_only:
        with executor_from_args(args) as ex:
            for e in chosen:
                if not quiet:
                    print(f"{e.dataset}: {records.command(e.dataset, e.identifier, seeds)}", flush=True)
                row = records.measure(e, seeds, executor=ex, progress=not quiet, fresh=not args.in_process)
                path = records.write_row(row, stored, beside=bool(e.beside_of))
                if not quiet:
                    for r in records.score_rows(row):
                        print(f"  {format_row(r)}")
                    m = row["measured"]
                    print(f"  stored -> {path} ({m['wall_seconds']:.1f} s wall, {m['cpu_seconds']:.1f} s CPU)")
    rows, missing = records.load_rows(entries, stored)
    data = records.write_outputs(entries, rows, missing, markdown, summary_path)
    for e in missing:  # a warning: -q leaves it out
        logging.getLogger(__name__).warning(
            "no stored row for %s (%s): run `piezotwin records --datasets %s`", e.dataset, e.identifier, e.dataset
        )
    if args.json:
        emit_json(data)
        return 0
    if not quiet:
        for dname, entry in data.items():
            print(
                f"{dname:<20} {entry['identifier']:<14} "
                + "  ".join(f"{t} {records.fmt_spread(v, _unit(rows[dname], t))}" for t, v in entry["rmse"].items())
            )
        print(f"{len(data)} rows, {len(missing)} missing -> {markdown}, {summary_path}")
    return 0


def _unit(row, test: str) -> str:
    from benchmarks.records import score_rows

    return next((r.get("units", "") for r in score_rows(row) if r["test"] == test), "")
