"""Options and helpers shared by several commands (one place for data-file and twin options)."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from sysid.data.io import read_record, write_record
from sysid.data.jsonio import clean_json
from sysid.data.record import FS_MAX, FS_MIN, Record

# ---------------------------------------------------------------------------- option types
# argparse calls these on the option's text; ArgumentTypeError becomes "argument --x: message", exit 2, one line.
SEED_MAX = 2**32 - 1


def seed_range(text: str) -> list[int]:
    """``A-B`` (inclusive) or one seed ``A``: non-negative integers, at most 1000 seeds."""
    parts = text.split("-")
    try:
        lo, hi = (int(parts[0]), int(parts[-1])) if len(parts) in (1, 2) else (None, None)
    except ValueError:
        lo = hi = None
    if lo is None or hi is None or lo < 0 or hi < lo or hi - lo >= 1000:
        raise argparse.ArgumentTypeError(f"expected seeds as A-B with 0 <= A <= B < A + 1000, got {text!r}")
    return list(range(lo, hi + 1))


def number(lo: float | None = None, hi: float | None = None, integer: bool = False, lo_open: bool = False):
    """An argparse ``type``: a finite number (an integer if ``integer``) in [lo, hi] (``(lo, hi]`` with
    ``lo_open``). Refuses nan, inf, huge values and text with one line."""

    def parse(text: str):
        try:
            v = float(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError(
                f"expected {'an integer' if integer else 'a number'}, got {text!r}"
            ) from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        if integer:
            if v != int(v):
                raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}")
            v = int(v)
        if lo is not None and (v < lo or (lo_open and v == lo)):
            raise argparse.ArgumentTypeError(f"must be {'>' if lo_open else '>='} {lo:g}, got {text}")
        if hi is not None and v > hi:
            raise argparse.ArgumentTypeError(f"must be <= {hi:g}, got {text}")
        return v

    parse.__name__ = "integer" if integer else "number"
    return parse


def FS(text: str) -> float:
    """argparse type of a sampling rate [Hz]: finite, positive, within the documented range FS_MIN..FS_MAX."""
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"expected a sampling rate in Hz, got {text!r}") from None
    if not math.isfinite(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"sampling rate fs must be positive and finite, got {text}")
    if not FS_MIN <= v <= FS_MAX:
        raise argparse.ArgumentTypeError(f"sampling rate {v:g} Hz outside the accepted range {FS_MIN:g}..{FS_MAX:g} Hz")
    return v


def SEED(text: str) -> int:
    """argparse type of a seed: an integer 0..2**32-1 (numpy's seed range; larger values are refused)."""
    try:
        v = float(text)
        ok = math.isfinite(v) and v == int(v) and 0 <= v <= SEED_MAX
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise argparse.ArgumentTypeError(f"seed must be a non-negative integer, got {text} (at most 2**32-1)")
    return int(v)


COUNT = number(1, 10**9, integer=True)  # a positive count (repeats, trials, workers, periods ...)
NONNEG_INT = number(0, 10**12, integer=True)
POSITIVE = number(0, 1e12, lo_open=True)  # a positive finite quantity (durations, amplitudes ...)


def add_set_arg(p: argparse.ArgumentParser, help: str) -> None:
    """The repeatable ``--set KEY=VALUE[,...]`` option (into ``args.set_``) of the commands that take identifier
    options."""
    p.add_argument("--set", dest="set_", action="append", default=[], metavar="KEY=VALUE[,...]", help=help)


def add_data_args(p: argparse.ArgumentParser) -> None:
    """Options of every command that reads a data file."""
    g = p.add_argument_group("data files")
    g.add_argument(
        "--fs",
        type=FS,
        help="sampling rate [Hz] when the file has no t column / fs (a file that has"
        " its own rate must agree with --fs, else it is refused)",
    )
    g.add_argument("--u-col", default="u", help="CSV column(s) of the input (comma-separated for several); default u")
    g.add_argument("--y-col", default="y", help="CSV column(s) of the output; default y")
    g.add_argument("--u-var", default="u", help="MAT variable of the input; default u")
    g.add_argument("--y-var", default="y", help="MAT variable of the output; default y")
    g.add_argument(
        "--fill-missing", action="store_true", help="interpolate missing (NaN/empty) samples instead of refusing them"
    )


def read_data(args: argparse.Namespace, path: str, require_y: bool = True) -> Record:
    return read_record(
        path,
        fs=args.fs,
        u_col=args.u_col,
        y_col=args.y_col,
        u_var=args.u_var,
        y_var=args.y_var,
        require_y=require_y,
        fill_missing=args.fill_missing,
    )


def same_fs(records: list[Record]) -> None:
    """Estimation and validation records must share one sampling rate (refused with both values)."""
    first = records[0]
    for r in records[1:]:
        if not math.isclose(r.fs, first.fs, rel_tol=1e-9):
            from sysid.errors import DataError

            raise DataError(
                f"{r.source}: sampling rate {r.fs:g} Hz differs from {first.source}'s {first.fs:g} Hz; "
                "records used together must share fs (resample one with piezotwin preprocess --resample)"
            )


# ---------------------------------------------------------------------------- checks before the work
INPUT_ARGS = ("file", "input", "est", "val", "data", "params")
OUTPUT_FILE_ARGS = ("output", "export", "plot")
OUTPUT_DIR_ARGS = ("plots", "report")
RECORD_OUTPUT_COMMANDS = ("signal", "preprocess", "simulate", "generate")


def preflight(args: argparse.Namespace) -> None:
    """Check every output the command will write before any work, so a wrong path fails at once: outputs that
    are an input file (by inode, symlinks included), folders that are files, a record output with an unknown
    suffix, a --storage that is a data file. Registers the inputs so that every writer refuses to overwrite them."""
    from sysid.data.io import SUPPORTED_SUFFIXES
    from sysid.data.safeio import check_output_dir, check_output_path, protect_inputs, same_file
    from sysid.errors import DataError

    inputs: list[str] = []
    for name in INPUT_ARGS:
        v = getattr(args, name, None)
        if isinstance(v, (list, tuple)):
            inputs += [str(x) for x in v if x]
        elif isinstance(v, str) and v:
            inputs.append(v)
    protect_inputs(inputs)
    for name in OUTPUT_FILE_ARGS:
        v = getattr(args, name, None)
        if isinstance(v, str) and v:
            check_output_path(v)
            collection = args.command == "generate" and (getattr(args, "grid", None) or getattr(args, "seeds", None))
            if name == "output" and args.command in RECORD_OUTPUT_COMMANDS and not collection:  # .h5: checked there
                suffix = Path(v).suffix.lower()
                if suffix not in SUPPORTED_SUFFIXES:
                    raise DataError(
                        f"{v}: unknown format {suffix or '(no suffix)'!r}; supported: {', '.join(SUPPORTED_SUFFIXES)}"
                    )
    for name in OUTPUT_DIR_ARGS:
        v = getattr(args, name, None)
        if isinstance(v, str) and v:
            check_output_dir(v)
            for src in inputs:
                if same_file(v, src):
                    raise DataError(f"{v}: output folder is the input {src}")
    storage = getattr(args, "storage", None)
    if isinstance(storage, str) and storage and "://" not in storage:
        for src in inputs:
            if same_file(storage, src):
                raise DataError(f"{storage}: --storage is the input {src}; give another file")


def add_twin_args(p: argparse.ArgumentParser, seed: bool = True) -> None:
    """Options of every command that builds a twin."""
    g = p.add_argument_group("twin configuration")
    g.add_argument("--params", metavar="FILE", help="saved calibration (parameter file) to start from")
    g.add_argument(
        "--set",
        dest="set_",
        action="append",
        default=[],
        metavar="KEY=VALUE[,...]",
        help="set parameters by name (SI units unless the name says otherwise); may repeat",
    )
    g.add_argument("--effect", action="append", default=[], metavar="NAME[:k=v,...]", help="add an effect; may repeat")
    g.add_argument("--without", action="append", default=[], metavar="NAME", help="remove an effect; may repeat")
    g.add_argument("--effects", metavar="LIST", help="exact set of effects (comma-separated); 'none' = bare core")
    if seed:
        g.add_argument("--seed", type=SEED, default=0, help="seed of the measurement noise (default 0)")


def twin_from_args(name: str, args: argparse.Namespace):
    from twins.registry import get_twin

    cls = get_twin(name)
    return cls.from_options(
        params_file=args.params,
        set_=args.set_,
        effect=args.effect,
        without=args.without,
        effects=args.effects,
        seed=getattr(args, "seed", 0),
    )


def emit_json(obj: Any, stream=None) -> None:
    json.dump(clean_json(obj), stream or sys.stdout, indent=2)
    (stream or sys.stdout).write("\n")


def save_output(record: Record, path: str) -> None:
    write_record(record, path)
