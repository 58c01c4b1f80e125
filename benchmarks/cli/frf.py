"""``piezotwin frf FILE [--periods P] [--json] [-o OUT.csv]``: nonparametric frequency response function.

Without ``--periods``: H1 estimate S_uy/S_uu with Welch averaging (``--window``, ``--nperseg``,
``--noverlap``) and the coherence. With ``--periods P`` (a periodic record, e.g. a multisine, of exactly P
periods): per-line average over the periods (``--drop K`` leading transient periods left out) at the excited
lines and the standard deviation of G per line from the period-to-period spread. The excited lines come from
the record's ``meta['signal']`` when ``piezotwin signal`` made the input, else from the input spectrum.

JSON (contract): arrays ``f_hz``, ``re``, ``im`` and ``coherence`` (non-periodic) or ``std`` (periodic), plus
``mag_db``, ``phase_deg`` and ``info``. ``-o OUT.csv`` writes the same columns; ``--plot FILE.png`` the
magnitude/phase figure. Files are written atomically.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from benchmarks.cli.common import add_data_args, emit_json, read_data
from sysid.data.record import Record
from sysid.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser(
        "frf",
        help="nonparametric FRF: H1/Welch with coherence, or periodic (multisine) with std",
        description="Nonparametric frequency response function of a record (SISO).",
    )
    p.add_argument("file", help="record with u and y")
    add_data_args(p)
    p.add_argument(
        "--periods",
        type=int,
        metavar="P",
        help="the record holds P periods of a periodic input "
        "(multisine): average per line over the periods, std of G from their spread (P >= 2)",
    )
    p.add_argument(
        "--drop",
        type=int,
        default=0,
        metavar="K",
        help="periodic: leave out the first K periods (transient); default 0",
    )
    p.add_argument(
        "--detrend",
        type=int,
        default=1,
        metavar="ORDER",
        help="periodic: remove a drift of this polynomial degree fitted to the period means (0: none; default 1)",
    )
    p.add_argument("--window", default="hann", help="H1: window of the Welch segments (scipy name; default hann)")
    p.add_argument("--nperseg", type=int, help="H1: segment length in samples (default min(N, 1024))")
    p.add_argument("--noverlap", type=int, help="H1: overlap in samples (default nperseg/2)")
    p.add_argument("--json", action="store_true", help="print the FRF as JSON")
    p.add_argument("-o", "--output", metavar="OUT.csv", help="write the FRF as CSV")
    p.add_argument("--plot", metavar="FILE.png", help="write the magnitude / phase (/ coherence) figure")
    p.set_defaults(func=run)


def excited_from_meta(rec: Record, n0: int) -> np.ndarray | None:
    """Excited lines recorded by ``piezotwin signal multisine`` in ``meta['signal']['info']`` when its period
    matches ``n0`` samples; None otherwise."""
    info = (rec.meta.get("signal") or {}).get("info") or {}
    bins = info.get("excited_bins")
    if bins is None or int(info.get("period_samples", -1)) != int(n0):
        return None
    return np.asarray(bins, dtype=np.int64)


def estimate(
    rec: Record,
    periods: int | None = None,
    drop: int = 0,
    window: str = "hann",
    nperseg: int | None = None,
    noverlap: int | None = None,
    detrend: int = 1,
):
    """The FRF of a record the way the command computes it (H1, or periodic with ``periods``)."""
    from sysid.linear.frf import frf_periodic, frf_welch

    rec.require_output()
    if rec.u.ndim != 1 or rec.output.ndim != 1:
        raise ConfigError(
            f"{rec.source}: frf handles one input and one output (got u{rec.u.shape}, y{rec.output.shape})"
        )
    if periods is None:
        if drop:
            raise ConfigError("--drop needs --periods")
        return frf_welch(rec.u, rec.y, rec.fs, window=window, nperseg=nperseg, noverlap=noverlap)
    if periods < 1:
        raise ConfigError(f"--periods must be >= 1, got {periods}")
    lines = excited_from_meta(rec, len(rec) // periods) if len(rec) % periods == 0 else None
    if detrend < 0:
        raise ConfigError(f"--detrend must be >= 0, got {detrend}")
    return frf_periodic(rec.u, rec.y, rec.fs, periods, drop=drop, lines=lines, detrend=detrend)


def to_json(frf) -> dict[str, Any]:
    out: dict[str, Any] = {"f_hz": frf.f_hz, "re": frf.G.real, "im": frf.G.imag}
    if frf.coherence is not None:
        out["coherence"] = frf.coherence
    else:
        out["std"] = frf.std
    out["mag_db"] = frf.magnitude_db
    out["phase_deg"] = frf.phase_deg
    out["info"] = {k: v for k, v in frf.info.items() if not isinstance(v, np.ndarray)}
    return out


def write_csv(columns: dict[str, Any], path: str) -> None:
    """Columns of equal length as a CSV with a header row, written atomically."""
    from sysid.data.io import atomic_path

    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            fh.write(",".join(names) + "\n")
            for row in data:
                fh.write(",".join(repr(float(v)) for v in row) + "\n")


def run(args: argparse.Namespace) -> int:
    rec = read_data(args, args.file)
    frf = estimate(rec, args.periods, args.drop, args.window, args.nperseg, args.noverlap, args.detrend)
    payload = to_json(frf)
    if args.output:
        cols = {k: payload[k] for k in ("f_hz", "re", "im", "mag_db", "phase_deg")}
        key = "coherence" if "coherence" in payload else "std"
        cols[key] = payload[key]
        write_csv(cols, args.output)
    if args.plot:
        from sysid.report.plots import plot_frf

        unit = f"{rec.units.get('y', '')}/{rec.units.get('u', '')}" if rec.units.get("y") else ""
        plot_frf(frf, args.plot, title=f"FRF of {args.file} ({frf.info['method']})", unit=unit)
    if args.json:
        emit_json({"file": args.file, **payload})
        return 0
    f = frf.f_hz
    print(f"{frf.info['method']}: {f.size} lines, {f[0]:g} .. {f[-1]:g} Hz")
    if frf.coherence is not None:
        good = np.isfinite(frf.coherence)
        print(f"coherence: median {np.median(frf.coherence[good]):.3f}, min {np.min(frf.coherence[good]):.3f}")
    step = max(1, f.size // 10)
    extra = "coherence" if frf.coherence is not None else "std"
    print(f"{'f [Hz]':>12} {'|G| [dB]':>10} {'phase [deg]':>12} {extra:>10}")
    vals = frf.coherence if frf.coherence is not None else frf.std
    for i in range(0, f.size, step):
        print(f"{f[i]:12.5g} {frf.magnitude_db[i]:10.3f} {frf.phase_deg[i]:12.2f} {vals[i]:10.3g}")
    for what, path in (("csv", args.output), ("figure", args.plot)):
        if path:
            print(f"{what} -> {path}")
    return 0
