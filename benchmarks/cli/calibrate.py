"""``piezotwin calibrate TWIN --data FILE [--val FILE] [--fit a,b] [--json] [-o PARAMS]``."""

from __future__ import annotations

import argparse

from benchmarks.cli.common import add_data_args, add_twin_args, emit_json, read_data, same_fs, twin_from_args


def register(sub) -> None:
    p = sub.add_parser("calibrate", help="fit a twin's parameters to a measured record (free-run output error)")
    p.add_argument("twin")
    p.add_argument("--data", required=True, metavar="FILE", help="estimation record")
    p.add_argument("--val", metavar="FILE", help="validation record")
    p.add_argument("--fit", metavar="NAMES", help="comma-separated parameters to fit (default: the twin's list)")
    add_data_args(p)
    add_twin_args(p)
    p.add_argument("--json", action="store_true")
    p.add_argument("-o", "--output", metavar="PARAMS", help="parameter file to write (JSON)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    twin = twin_from_args(args.twin, args)
    data = read_data(args, args.data)
    val = read_data(args, args.val) if args.val else None
    same_fs([data] + ([val] if val is not None else []))
    names = [n.strip() for n in args.fit.split(",") if n.strip()] if args.fit is not None else None
    result = twin.calibrate(data, val=val, names=names)
    summary = result.to_dict()
    if args.output:
        result.twin.save_params(args.output, extra={"calibration": summary})
        summary["params_file"] = args.output
    if args.json:
        emit_json(summary)
        return 0
    print(f"calibrated {args.twin} ({summary['n_evaluations']} simulations, {summary['seconds']:.1f} s)")
    for k, v in summary["parameters"].items():
        se = v["stderr"]
        print(
            f"  {k:<22} {v['value']:.6g} ± {se:.2g} {v['unit']}"
            if se is not None
            else f"  {k:<22} {v['value']:.6g} {v['unit']}"
        )
    for part, s in summary["scores"].items():
        print(f"  {part:<11} R2 = {s['r2']:.5f}  NRMSE = {s['nrmse']:.5f}")
    if args.output:
        print(f"  parameters -> {args.output}")
    return 0
