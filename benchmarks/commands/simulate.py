"""``piezotwin simulate TWIN --input FILE -o OUT`` and ``piezotwin generate TWIN PROTOCOL -o OUT``."""

from __future__ import annotations

import argparse

from benchmarks.commands.common import add_data_args, add_twin_args, read_data, twin_from_args
from sysid.errors import ConfigError
from sysid.io import write_record


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
    g.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="protocol option (see the twin's protocol docs), may repeat")
    g.add_argument("-o", "--output", required=True, metavar="OUT", help="output record (.npz)")
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

        from sysid.record import FS_MAX, FS_MIN

        try:
            v = float(opts["fs"])
        except ValueError:
            v = math.nan  # not a number: the twin's own check names it
        if math.isfinite(v) and v > 0 and not FS_MIN <= v <= FS_MAX:
            raise ConfigError(f"--option fs: sampling rate {v:g} Hz outside the accepted range {FS_MIN:g}..{FS_MAX:g} Hz")
    rec = twin.generate(args.protocol, **opts)
    write_record(rec, args.output)
    print(f"generated {args.twin} {args.protocol}: {len(rec)} samples at {rec.fs:g} Hz -> {args.output}")
    return 0
