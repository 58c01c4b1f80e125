"""``piezotwin sweep TWIN PARAM=v1,v2,... [--protocol P] [--json] [--report DIR]`` — a parameter study.

For each value of one twin parameter (any field of the twin's parameter dataclass, e.g. ``distance_m``,
``temperature_c``, ``fluid``), the twin is rebuilt with that value (on top of ``--params/--set/--effect``)
and its ``sweep_metrics(protocol)`` are tabulated. A twin that defines no ``sweep_metrics`` is refused with
a one-line message. With ``--report DIR``: ``sweep_<param>_spectra.png`` (when the twin has
``sweep_spectrum``) and ``sweep_<param>_metrics.png`` (each numeric figure against the parameter), plus
``sweep_<param>.json``. ``--workers N`` / ``--scheduler ADDRESS`` run the values as Dask tasks
(:mod:`benchmarks.execution`); the rows keep the order of the values. The study itself:
:mod:`benchmarks.sweep`; this module parses, calls and prints.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from benchmarks.cli.common import add_twin_args, emit_json, twin_from_args
from benchmarks.execution import add_execution_args, executor_from_args
from benchmarks.sweep import parse_spec, public, sweep, write_report


def register(sub) -> None:
    p = sub.add_parser("sweep", help="vary one twin parameter and tabulate the channel's figures")
    p.add_argument("twin")
    p.add_argument("spec", metavar="PARAM=v1,v2,...", help="parameter and its values (comma-separated)")
    p.add_argument("--protocol", help="protocol used for the identified-model figure (twin default otherwise)")
    p.add_argument("--no-identify", action="store_true", help="skip the identified-model accuracy column")
    add_twin_args(p)
    p.add_argument("--json", action="store_true")
    p.add_argument("--report", metavar="DIR", help="write PNG plots and the JSON table into DIR")
    add_execution_args(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    twin = twin_from_args(args.twin, args)
    name, values = parse_spec(args.spec, type(twin.params))
    with executor_from_args(args) as ex:
        result = sweep(
            twin, name, values, args.protocol, identify=not args.no_identify, executor=ex, progress=not args.json
        )
    if args.report:
        result["report_files"] = write_report(result, Path(args.report))
    if args.json:
        emit_json(public(result))
        return 0
    cols = ["peak_frequency_hz", "peak_gain_db", "bandwidth_hz", "time_of_flight_s", "identified_model_r2"]
    cols = [c for c in cols if c in result["rows"][0]] or [k for k in result["rows"][0] if k != "value"]
    print(f"sweep {result['twin']} {name} [{result['unit']}]")
    print("  " + f"{'value':>12}" + "".join(f"{c:>22}" for c in cols))
    for r in result["rows"]:
        cells = []
        for c in cols:
            v = r.get(c)
            cells.append(f"{'null':>22}" if v is None else f"{v:>22.6g}" if isinstance(v, float) else f"{str(v):>22}")
        print("  " + f"{str(r['value']):>12}" + "".join(cells))
    notes = {r.get("identified_model_note") for r in result["rows"] if r.get("identified_model_note")}
    for n in notes:
        print(f"  note: {n}")
    for f in result.get("report_files", []):
        print(f"  wrote {f}")
    return 0
