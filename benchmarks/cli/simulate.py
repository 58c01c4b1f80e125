"""``piezotwin simulate TWIN --input FILE -o OUT`` and ``piezotwin generate TWIN PROTOCOL -o OUT``.

``generate ... --grid distance_m=0.02-0.04-0.08,temperature_c=20-40 --seeds 0-9 -o OUT.h5`` generates a
collection (one record per grid point and seed) as HDF5 plus an index table (:mod:`benchmarks.collection`),
in this process or on Dask (``--workers N`` / ``--scheduler ADDRESS``, :mod:`benchmarks.execution`).
"""

from __future__ import annotations

import argparse

from benchmarks.cli.common import add_data_args, add_twin_args, read_data, twin_from_args
from benchmarks.execution import add_execution_args, executor_from_args
from sysid.data.io import write_record
from sysid.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser("simulate", help="simulate a twin on an input file")
    p.add_argument("twin")
    p.add_argument("--input", required=True, metavar="FILE", help="record with u (and t or --fs)")
    add_data_args(p)
    add_twin_args(p)
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output record (.npz)")
    p.set_defaults(func=run_simulate)

    g = sub.add_parser("generate", help="run one of a twin's protocols and save the record")
    g.add_argument("twin")
    g.add_argument("protocol")
    add_twin_args(g)
    g.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="protocol option (see the twin's protocol docs), may repeat",
    )
    g.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="OUT",
        help="output record (.npz); with --grid/--seeds an HDF5 collection (.h5)",
    )
    g.add_argument(
        "--grid",
        metavar="P=V1-V2,...",
        help="parameter grid: items separated by ',', values by '-' "
        "(e.g. distance_m=0.02-0.04-0.08,temperature_c=20-40); writes an HDF5 collection",
    )
    g.add_argument("--seeds", metavar="A-B", help="noise seeds of the collection (e.g. 0-9 or 0,3,7; replaces --seed)")
    g.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_execution_args(g)
    g.set_defaults(func=run_generate)


def run_simulate(args: argparse.Namespace) -> int:
    twin = twin_from_args(args.twin, args)
    rec = read_data(args, args.input, require_y=False)
    out = twin.simulate_record(rec)
    write_record(out, args.output)
    print(f"simulated {args.twin} on {len(rec)} samples at {rec.fs:g} Hz -> {args.output}")
    return 0


def run_generate(args: argparse.Namespace) -> int:
    from sysid.config import parse_assignments

    twin = twin_from_args(args.twin, args)
    twin.check_protocol(args.protocol)
    opts = parse_assignments(args.option, "--option")
    if "fs" in opts:  # the documented rate range (a huge fs would otherwise overflow or exhaust memory)
        import math

        from sysid.data.record import FS_MAX, FS_MIN

        try:
            v = float(opts["fs"])
        except ValueError:
            v = math.nan  # not a number: the twin's own check names it
        if math.isfinite(v) and v > 0 and not FS_MIN <= v <= FS_MAX:
            raise ConfigError(
                f"--option fs: sampling rate {v:g} Hz outside the accepted range {FS_MIN:g}..{FS_MAX:g} Hz"
            )
    if args.grid or args.seeds:
        return _run_collection(args, twin)
    rec = twin.generate(args.protocol, **opts)
    write_record(rec, args.output)
    print(f"generated {args.twin} {args.protocol}: {len(rec)} samples at {rec.fs:g} Hz -> {args.output}")
    return 0


def _run_collection(args: argparse.Namespace, twin) -> int:
    from benchmarks.collection import generate_collection, parse_grid_spec, parse_seeds
    from sysid.config import parse_assignments

    grid = parse_grid_spec(args.grid, type(twin.params)) if args.grid else {}
    seeds = parse_seeds(args.seeds) if args.seeds else [args.seed]
    options = parse_assignments(args.option, "--option")
    with executor_from_args(args) as ex:
        out = generate_collection(
            twin, args.protocol, grid, seeds, args.output, options=options, executor=ex, progress=not args.no_progress
        )
    print(f"generated {out['records']} {args.twin} {args.protocol} records -> {out['file']} (index {out['index']})")
    return 0
