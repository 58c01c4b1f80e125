"""``piezotwin signal KIND --fs HZ --duration S [...] -o FILE``: write an input-only Record (``u``).

Kinds: ``multisine``, ``chirp``, ``sine``, ``stepped-sine``, ``prbs``, ``aprbs`` and the dissertation's own
signals ``thesis-cantilever`` (multisine of §3.1), ``thesis-acoustic`` (multisine of §3.2) and
``thesis-chirp`` (``--duration 0.1`` or ``0.001``; §3.2), which need no other option.
``--amplitude`` is the peak value unless ``--rms`` is given (then the RMS value).
The generator's parameters and its report (crest factor, excited lines ...) go to ``meta["signal"]``.
"""

from __future__ import annotations

import argparse
import math
from typing import Any

import numpy as np

from benchmarks.cli.common import COUNT, FS, POSITIVE, SEED, emit_json, number
from sysid.data.io import write_record
from sysid.data.record import Record
from sysid.errors import ConfigError
from sysid.signals import excitation as signals

KINDS = (
    "multisine",
    "chirp",
    "sine",
    "stepped-sine",
    "prbs",
    "aprbs",
    "thesis-cantilever",
    "thesis-acoustic",
    "thesis-chirp",
)


def parse_pair(text: str, option: str, allow_empty_max: bool = False) -> tuple[float, float | None]:
    """``"A:B"`` -> (A, B) as floats; one-line ConfigError otherwise."""
    parts = str(text).split(":")
    if len(parts) != 2:
        raise ConfigError(f"{option} must be MIN:MAX, got {text!r}")
    try:
        a = float(parts[0])
        b = None if (allow_empty_max and parts[1].strip() == "") else float(parts[1])
    except ValueError:
        raise ConfigError(f"{option} must be two numbers MIN:MAX, got {text!r}") from None
    if not math.isfinite(a) or (b is not None and not math.isfinite(b)):
        raise ConfigError(f"{option} must be finite, got {text!r}")
    return a, b


def register(sub) -> None:
    p = sub.add_parser(
        "signal",
        help="generate an excitation signal (record with u only)",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    p.add_argument("kind", choices=KINDS)
    p.add_argument("--fs", type=FS, help="sampling rate [Hz]")
    p.add_argument("--duration", type=POSITIVE, help="length [s]")
    p.add_argument(
        "--band",
        metavar="FMIN:FMAX",
        help="multisine: excited band [Hz] (FMAX may be empty: up to Nyquist); chirp: start:end frequency [Hz]",
    )
    p.add_argument("--components", type=COUNT, help="multisine: number of lines (default: every grid line in the band)")
    p.add_argument("--resolution", type=POSITIVE, help="multisine: line spacing [Hz] (default 1/period)")
    p.add_argument(
        "--amplitude", type=number(-1e12, 1e12), default=1.0, help="peak value (RMS value with --rms); default 1"
    )
    p.add_argument("--rms", action="store_true", help="--amplitude is the RMS value")
    p.add_argument("--phase", choices=signals.PHASES, default="random", help="multisine phases (default random)")
    p.add_argument("--grid", choices=signals.GRIDS, default="full", help="multisine line grid (default full)")
    p.add_argument(
        "--detection-fraction",
        type=number(0, 1),
        default=0.0,
        help="multisine: fraction of lines left out at random as detection lines (default 0)",
    )
    p.add_argument("--periods", type=COUNT, default=1, help="number of periods in --duration (multisine, chirp, prbs)")
    p.add_argument("--seed", type=SEED, default=0, help="seed of random phases / detection lines / APRBS (default 0)")
    p.add_argument("--method", choices=("linear", "log"), default="linear", help="chirp sweep law (default linear)")
    p.add_argument("--periodic", action="store_true", help="chirp: periodic chirp of eq. 2-2 (f*T0 integers)")
    p.add_argument("--freq", type=number(0, 1e9), help="sine: frequency [Hz]")
    p.add_argument(
        "--sine-phase", type=number(-1e6, 1e6), default=0.0, help="sine/chirp: initial phase [rad] (cos form, eq. 2-3)"
    )
    p.add_argument("--freqs", help="stepped-sine: comma-separated frequencies [Hz]")
    p.add_argument("--settle", type=number(0, 1e6), default=0.0, help="stepped-sine: settling time per step [s]")
    p.add_argument("--cycles", type=COUNT, default=10, help="stepped-sine: periods measured per step (default 10)")
    p.add_argument(
        "--order",
        type=number(2, 40, integer=True),
        default=10,
        help="prbs: LFSR order, period 2^order-1 bits (default 10)",
    )
    p.add_argument("--bit-samples", type=COUNT, default=1, help="prbs: samples per bit (default 1)")
    p.add_argument("--hold", metavar="MIN:MAX", help="aprbs: hold time range [s] (default 10..100 samples)")
    p.add_argument(
        "--levels", type=number(2, 10**6, integer=True), help="aprbs: number of discrete levels (default: continuous)"
    )
    p.add_argument(
        "--truncate", type=COUNT, help="thesis-acoustic: keep the first N samples (the dissertation kept 5000)"
    )
    p.add_argument("--unit", default="V", help="unit of u (default V)")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="output record (.npz, .csv or .mat)")
    p.set_defaults(func=run)


def _need(args: argparse.Namespace, *names: str) -> None:
    for n in names:
        if getattr(args, n) is None:
            raise ConfigError(f"signal {args.kind} needs --{n.replace('_', '-')}")


def build(args: argparse.Namespace) -> tuple[np.ndarray, float, dict, dict]:
    """(u, fs, params, info) for the parsed arguments."""
    kind = args.kind
    info: dict = {}
    params: dict = {}
    amp = args.amplitude
    if kind == "thesis-cantilever":
        u, info = signals.thesis_cantilever_multisine(seed=args.seed, return_info=True)
        return u, 10e3, {"seed": args.seed}, info
    if kind == "thesis-acoustic":
        u, info = signals.thesis_acoustic_multisine(seed=args.seed, truncate=args.truncate, return_info=True)
        return u, 100e6, {"seed": args.seed, "truncate": args.truncate}, info
    if kind == "thesis-chirp":
        _need(args, "duration")
        return signals.thesis_chirp(args.duration), 100e6, {"duration": args.duration}, {}
    _need(args, "fs")
    fs = args.fs
    if kind == "multisine":
        if args.duration is None and args.resolution is None:
            raise ConfigError("signal multisine needs --duration or --resolution")
        band = parse_pair(args.band, "--band", allow_empty_max=True) if args.band else (0.0, None)
        params = dict(
            duration=args.duration,
            band=band,
            components=args.components,
            resolution=args.resolution,
            amplitude=amp,
            rms=args.rms,
            phase=args.phase,
            grid=args.grid,
            detection_fraction=args.detection_fraction,
            periods=args.periods,
            seed=args.seed,
        )
        u, info = signals.multisine(fs, return_info=True, **params)
        return u, fs, params, info
    if kind not in ("prbs", "stepped-sine"):
        _need(args, "duration")
    if kind == "chirp":
        _need(args, "band")
        f0, f1 = parse_pair(args.band, "--band")
        params = dict(
            duration=args.duration,
            f0=f0,
            f1=f1,
            amplitude=1.0 if args.rms else amp,
            method=args.method,
            periodic=args.periodic,
            phase=args.sine_phase,
            periods=args.periods,
        )
        u = signals.chirp(fs, **params)
    elif kind == "sine":
        _need(args, "freq")
        params = dict(duration=args.duration, freq=args.freq, amplitude=1.0 if args.rms else amp, phase=args.sine_phase)
        u = signals.sine(fs, **params)
    elif kind == "stepped-sine":
        _need(args, "freqs")
        try:
            freqs = [float(f) for f in args.freqs.split(",") if f.strip()]
        except ValueError:
            raise ConfigError(f"--freqs must be comma-separated numbers, got {args.freqs!r}") from None
        params = dict(freqs=freqs, amplitude=1.0 if args.rms else amp, settle=args.settle, cycles=args.cycles)
        u, info = signals.stepped_sine(fs, return_info=True, **params)
    elif kind == "prbs":
        params = dict(
            order=args.order,
            duration=args.duration,
            periods=args.periods,
            bit_samples=args.bit_samples,
            amplitude=1.0 if args.rms else amp,
        )
        u = signals.prbs(fs, **params)
    elif kind == "aprbs":
        lo_hold, hi_hold = parse_pair(args.hold, "--hold") if args.hold else (None, None)
        a = 1.0 if args.rms else amp
        params = dict(
            duration=args.duration,
            low=-a,
            high=a,
            min_hold=lo_hold,
            max_hold=hi_hold,
            levels=args.levels,
            seed=args.seed,
        )
        u, info = signals.aprbs(fs, return_info=True, **params)
    else:  # pragma: no cover - argparse restricts the choices
        raise ConfigError(f"unknown signal kind {kind!r}")
    if args.rms:
        r = float(np.sqrt(np.mean(u * u)))
        if r == 0:
            raise ConfigError(f"signal {kind} is identically zero; cannot scale to an RMS value")
        u = u * (amp / r)
        params["rms"] = amp
    return u, fs, params, info


def _expected_samples(args: argparse.Namespace) -> float:
    """Samples the request would generate (before allocating anything), for the memory guard."""
    fs = args.fs or 0.0
    if args.kind == "thesis-chirp":
        return (args.duration or 0.0) * 100e6
    if args.kind == "prbs":
        n = (2**args.order - 1) * args.bit_samples * args.periods
        return max(n, (args.duration or 0.0) * fs)
    if args.kind == "stepped-sine":
        try:
            freqs = [float(f) for f in (args.freqs or "").split(",") if f.strip()]
        except ValueError:
            return 0.0
        return sum(fs * (args.settle + args.cycles / f) for f in freqs if f > 0)
    if args.kind == "multisine" and args.duration is None and args.resolution:
        return fs / args.resolution * args.periods
    return (args.duration or 0.0) * fs


def run(args: argparse.Namespace) -> int:
    from sysid.data.safeio import check_memory

    check_memory(_expected_samples(args), f"signal {args.kind}", copies=6)
    if args.amplitude is not None and (not math.isfinite(args.amplitude) or args.amplitude <= 0):
        raise ConfigError(f"--amplitude must be positive, got {args.amplitude}")
    u, fs, params, info = build(args)
    summary = {
        "kind": args.kind,
        "samples": int(u.size),
        "fs": fs,
        "duration_s": u.size / fs,
        "peak": float(np.max(np.abs(u))),
        "rms": float(np.sqrt(np.mean(u * u))),
        "crest_factor": signals.crest_factor(u),
    }
    info = {k: v for k, v in info.items() if k != "phases_rad"}  # the signal itself is saved; keep meta small
    meta: dict[str, Any] = {
        "signal": {
            "kind": args.kind,
            "params": params,
            "info": info,
            **{k: summary[k] for k in ("peak", "rms", "crest_factor")},
        }
    }
    if "steps" in info:
        meta["segments"] = [
            {"start": s["measure_start"], "stop": s["stop"], "freq_hz": s["freq_hz"]} for s in info["steps"]
        ]
    write_record(
        Record(u=u, y=None, fs=fs, units={"u": args.unit, "y": ""}, meta=meta, source=args.output), args.output
    )
    if args.json:
        emit_json({**summary, "output": args.output})
    else:
        print(
            f"{args.kind}: {u.size} samples at {fs:g} Hz ({u.size / fs:g} s), peak {summary['peak']:.4g},"
            f" crest factor {summary['crest_factor']:.3f} -> {args.output}"
        )
    return 0
