"""Options and helpers shared by several commands (one place for data-file and twin options)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Any

import numpy as np

from sysid.io import read_record, write_record
from sysid.record import Record


def add_data_args(p: argparse.ArgumentParser) -> None:
    """Options of every command that reads a data file (DESIGN.md)."""
    g = p.add_argument_group("data files")
    g.add_argument("--fs", type=float, help="sampling rate [Hz] when the file has no t column / fs (a file that has"
                   " its own rate must agree with --fs, else it is refused)")
    g.add_argument("--u-col", default="u", help="CSV column(s) of the input (comma-separated for several); default u")
    g.add_argument("--y-col", default="y", help="CSV column(s) of the output; default y")
    g.add_argument("--u-var", default="u", help="MAT variable of the input; default u")
    g.add_argument("--y-var", default="y", help="MAT variable of the output; default y")
    g.add_argument("--fill-missing", action="store_true", help="interpolate missing (NaN/empty) samples instead of refusing them")


def read_data(args: argparse.Namespace, path: str, require_y: bool = True) -> Record:
    return read_record(path, fs=args.fs, u_col=args.u_col, y_col=args.y_col, u_var=args.u_var, y_var=args.y_var,
                       require_y=require_y, fill_missing=args.fill_missing)


def add_twin_args(p: argparse.ArgumentParser, seed: bool = True) -> None:
    """Options of every command that builds a twin (DESIGN.md)."""
    g = p.add_argument_group("twin configuration")
    g.add_argument("--params", metavar="FILE", help="saved calibration (parameter file) to start from")
    g.add_argument("--set", dest="set_", action="append", default=[], metavar="KEY=VALUE[,...]",
                   help="set parameters by name (SI units unless the name says otherwise); may repeat")
    g.add_argument("--effect", action="append", default=[], metavar="NAME[:k=v,...]", help="add an effect; may repeat")
    g.add_argument("--without", action="append", default=[], metavar="NAME", help="remove an effect; may repeat")
    g.add_argument("--effects", metavar="LIST", help="exact set of effects (comma-separated); 'none' = bare core")
    if seed:
        g.add_argument("--seed", type=int, default=0, help="seed of the measurement noise (default 0)")


def twin_from_args(name: str, args: argparse.Namespace):
    from twins.registry import get_twin

    cls = get_twin(name)
    return cls.from_options(params_file=args.params, set_=args.set_, effect=args.effect, without=args.without,
                            effects=args.effects, seed=getattr(args, "seed", 0))


def clean_json(obj: Any) -> Any:
    """Make ``obj`` strict-JSON: numpy scalars/arrays to Python, nan/inf to null."""
    if isinstance(obj, dict):
        return {str(k): clean_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return clean_json(obj.tolist())
    if isinstance(obj, np.generic):
        return clean_json(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def emit_json(obj: Any, stream=None) -> None:
    json.dump(clean_json(obj), stream or sys.stdout, indent=2)
    (stream or sys.stdout).write("\n")


def save_output(record: Record, path: str) -> None:
    write_record(record, path)
