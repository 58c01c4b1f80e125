"""``piezotwin preprocess FILE [steps...] -o OUT``: apply preprocessing steps in the order given.

Steps (each may repeat; they run in command-line order, e.g. ``--moving-average 100 --resample 6.75e6``
smooths first): ``--remove-offset``, ``--detrend [ORDER]``, ``--outliers [HALFWIDTH[:NSIGMA]]`` (Hampel),
``--moving-average N``, ``--decimate Q``, ``--resample FS``, ``--bandpass FMIN:FMAX[:ORDER]``,
``--segment LENGTH[:OVERLAP]``, ``--suggest-rate`` (Aguirre's covariance rule; reports, changes nothing).
``--fill-missing`` is the read option shared by every data command: missing samples are interpolated when
the file is read, i.e. always before every other step (no other step can work on missing samples), and it
is recorded as the first entry of ``meta["preprocessing"]``. Each step is recorded there as
``{"step", "params", "changes"}``.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

from benchmarks.cli.common import add_data_args, emit_json, read_data
from sysid.data.io import write_record
from sysid.data.record import FS_MAX, FS_MIN
from sysid.errors import ConfigError


class _Step(argparse.Action):
    """Append ``(step, raw value)`` to ``namespace.steps`` so the steps keep their command-line order."""

    def __init__(self, option_strings, dest, step: str, **kw):
        self.step = step
        super().__init__(option_strings, dest="steps", **kw)

    def __call__(self, parser, namespace, values, option_string=None):
        steps = list(getattr(namespace, "steps", None) or [])
        steps.append((self.step, values, option_string))
        namespace.steps = steps


def register(sub) -> None:
    p = sub.add_parser(
        "preprocess",
        help="offset/trend/outliers/moving average/decimation/resampling/band-pass ...",
        description="Apply preprocessing steps to a record, in the order given on the command line.",
    )
    p.add_argument("file")
    add_data_args(p)
    g = p.add_argument_group("steps (applied in the order given)")
    g.add_argument("--remove-offset", action=_Step, step="remove_offset", nargs=0, help="subtract the mean")
    g.add_argument(
        "--detrend",
        action=_Step,
        step="detrend",
        nargs="?",
        const="1",
        metavar="ORDER",
        help="remove a polynomial trend (default order 1: linear)",
    )
    g.add_argument(
        "--outliers",
        action=_Step,
        step="hampel",
        nargs="?",
        const="",
        metavar="HALFWIDTH[:NSIGMA]",
        help="Hampel filter: replace samples beyond NSIGMA robust std of the local median (default 10:3)",
    )
    g.add_argument(
        "--moving-average",
        action=_Step,
        step="moving_average",
        metavar="N",
        help="centred moving average of N samples (the dissertation used 100)",
    )
    g.add_argument("--decimate", action=_Step, step="decimate", metavar="Q", help="anti-aliased decimation by Q")
    g.add_argument(
        "--resample", action=_Step, step="resample", metavar="FS", help="anti-aliased rational resampling to FS Hz"
    )
    g.add_argument(
        "--bandpass",
        action=_Step,
        step="bandpass",
        metavar="FMIN:FMAX[:ORDER]",
        help="zero-phase Butterworth band-pass (default order 5)",
    )
    g.add_argument(
        "--segment",
        action=_Step,
        step="segment",
        metavar="LENGTH[:OVERLAP]",
        help="mark segments of LENGTH samples in meta['segments']",
    )
    g.add_argument(
        "--suggest-rate",
        action=_Step,
        step="suggest_rate",
        nargs=0,
        help="report the decimation factor of the covariance rule (Aguirre)",
    )
    p.add_argument(
        "--signals",
        choices=("u", "y", "both"),
        default="both",
        help="signals the filtering steps act on (default both; decimation/resampling always act on both)",
    )
    p.add_argument("--json", action="store_true", help="print the recorded steps as JSON")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output record")
    p.set_defaults(func=run, steps=[])


def _num(text: Any, option: str, integer: bool = False, lo: float | None = None, hi: float | None = None) -> float:
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise ConfigError(f"{option} expects a number, got {text!r}") from None
    if not math.isfinite(v):
        raise ConfigError(f"{option} must be finite, got {text!r}")
    if lo is not None and v < lo or hi is not None and v > hi:
        raise ConfigError(f"{option}: {text} outside the accepted range {lo:g}..{hi if hi is not None else math.inf:g}")
    if integer:
        if v != int(v):
            raise ConfigError(f"{option} expects an integer, got {text!r}")
        return int(v)
    return v


_BIG = 10**12  # sample counts beyond this are no record's


def to_steps(raw: list[tuple[str, str | list, str]], signals: str = "both") -> list[dict]:
    """Command-line (step, value, option) triples -> apply_steps dicts (one-line ConfigError on bad values)."""
    out = []
    per_signal = {"remove_offset", "detrend", "hampel", "moving_average", "bandpass"}
    for name, value, opt in raw:
        d: dict = {"step": name}
        if name == "detrend":
            d["order"] = _num(value, opt, integer=True, lo=0, hi=20)
        elif name == "hampel" and value:
            parts = str(value).split(":")
            if len(parts) > 2:
                raise ConfigError(f"{opt} expects HALFWIDTH[:NSIGMA], got {value!r}")
            d["window"] = _num(parts[0], opt, integer=True, lo=1, hi=_BIG)
            if len(parts) == 2:
                d["n_sigma"] = _num(parts[1], opt, lo=0, hi=1e6)
        elif name == "moving_average":
            d["span"] = _num(value, opt, integer=True, lo=1, hi=_BIG)
        elif name == "decimate":
            d["q"] = _num(value, opt, integer=True, lo=1, hi=_BIG)
        elif name == "resample":
            d["fs_new"] = _num(value, opt, lo=FS_MIN, hi=math.inf)  # the library refuses rates it cannot reach
        elif name == "bandpass":
            parts = str(value).split(":")
            if len(parts) not in (2, 3):
                raise ConfigError(f"{opt} expects FMIN:FMAX[:ORDER], got {value!r}")
            d["fmin"], d["fmax"] = _num(parts[0], opt, lo=0, hi=FS_MAX), _num(parts[1], opt, lo=0, hi=FS_MAX)
            if len(parts) == 3:  # a Butterworth order beyond ~20 is numerically meaningless; 64 is generous
                d["order"] = _num(parts[2], opt, integer=True, lo=1, hi=64)
        elif name == "segment":
            parts = str(value).split(":")
            if len(parts) not in (1, 2):
                raise ConfigError(f"{opt} expects LENGTH[:OVERLAP], got {value!r}")
            d["length"] = _num(parts[0], opt, integer=True, lo=1, hi=_BIG)
            if len(parts) == 2:
                d["overlap"] = _num(parts[1], opt, integer=True, lo=0, hi=_BIG)
        if name in per_signal:
            d["signals"] = signals
        out.append(d)
    return out


def run(args: argparse.Namespace) -> int:
    from sysid.signals.preprocess import apply_steps  # imported here: numba is slow to import for every CLI start

    steps = to_steps(args.steps, args.signals)
    if not steps and not args.fill_missing:
        raise ConfigError("preprocess: give at least one step (see piezotwin preprocess --help)")
    rec = read_data(args, args.file, require_y=False)
    for st in steps:  # memory guard: the largest record a resampling step would build
        if st["step"] == "resample" and st["fs_new"] <= FS_MAX:
            from sysid.data.safeio import check_memory

            check_memory(
                len(rec) * max(1.0, st["fs_new"] / rec.fs) * max(rec.n_inputs + rec.n_outputs, 1),
                f"preprocess --resample {st['fs_new']:g}",
                copies=4,
            )
    n0 = len(rec.meta.get("preprocessing", []))
    out = apply_steps(rec, steps)
    write_record(out, args.output)
    log = out.meta["preprocessing"]
    first = n0
    if (
        n0
        and log[n0 - 1].get("step") == "fill_missing"
        and log[n0 - 1].get("params", {}).get("at") == "read"
        and args.fill_missing
    ):
        first = n0 - 1  # filled while reading this file
    done = log[first:]
    if args.json:
        emit_json({"input": args.file, "output": args.output, "fs": out.fs, "samples": len(out), "steps": done})
        return 0
    for entry in done:
        ch = entry.get("changes", {})
        if entry["step"] == "suggest_rate":
            extra = (
                f": tau_linear={ch['tau_linear']}, tau_nonlinear={ch['tau_nonlinear']} samples -> decimation factor"
                f" {ch['factor']} (fs {ch.get('fs_suggested', float('nan')):g} Hz)"
            )
        elif entry["step"] == "hampel":
            extra = f": replaced {ch.get('n_replaced')}"
        elif "fs_after" in ch:
            extra = f": {ch['n_before']} -> {ch['n_after']} samples, {ch['fs_before']:g} -> {ch['fs_after']:g} Hz"
        elif entry["step"] == "fill_missing":
            extra = f": filled {ch.get('filled_indices', entry.get('filled_indices'))}"
        else:
            extra = ""
        print(f"{entry['step']}{extra}")
    print(f"{len(out)} samples at {out.fs:g} Hz -> {args.output}")
    return 0
