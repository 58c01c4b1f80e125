"""``piezotwin bla FILE [FILE ...] --periods P [--json]``: Best Linear Approximation and nonlinearity detection.

One file per realisation of a random-phase multisine, each holding exactly P periods (``--drop K`` leading
transient periods are left out). Robust method of Pintelon & Schoukens (:mod:`sysid.linear.bla`): G_BLA, its noise
variance (period spread) and its nonlinear-distortion variance (realisation spread, two or more files), and
the odd / even distortion levels in dB over the noise floor at the detection lines, with a verdict
``linear`` | ``odd`` | ``even`` | ``odd+even``.

JSON (contract): arrays ``f_hz``, ``re``, ``im``, ``var_noise``, ``var_distortion`` and ``nonlinearity`` =
{``verdict``, ``odd_db``, ``even_db``, ...}; also ``var_total`` and ``info``. ``-o OUT.csv`` writes the
arrays, ``--plot FILE.png`` the figure (G_BLA with noise and distortion levels, detection lines).
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from benchmarks.cli.common import add_data_args, emit_json, read_data
from benchmarks.cli.frf import excited_from_meta, write_csv
from sysid.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser(
        "bla",
        help="Best Linear Approximation from multisine realisations; odd/even distortion",
        description="Best Linear Approximation (robust method) and nonlinearity detection.",
    )
    p.add_argument("files", nargs="+", metavar="FILE", help="one record per multisine realisation (u and y)")
    p.add_argument("--periods", type=int, required=True, metavar="P", help="periods in each record")
    p.add_argument("--drop", type=int, default=0, metavar="K", help="leave out the first K (transient) periods")
    p.add_argument(
        "--detrend",
        type=int,
        default=1,
        metavar="ORDER",
        help="periodic: remove a drift of this polynomial degree fitted to the period means (0: none; default 1)",
    )
    p.add_argument(
        "--alpha", type=float, default=1e-3, help="false-alarm probability of the detection-line test (default 1e-3)"
    )
    add_data_args(p)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("-o", "--output", metavar="OUT.csv", help="write f_hz, re, im, var_noise, var_distortion as CSV")
    p.add_argument("--plot", metavar="FILE.png", help="write the BLA / noise / distortion / detection figure")
    p.set_defaults(func=run)


def estimate(records, periods: int, drop: int = 0, alpha: float = 1e-3, detrend: int = 1):
    """The BLA of the records (one per realisation) the way the command computes it."""
    from sysid.linear.bla import best_linear_approximation

    if periods < 1:
        raise ConfigError(f"--periods must be >= 1, got {periods}")
    if detrend < 0:
        raise ConfigError(f"--detrend must be >= 0, got {detrend}")
    if not 0.0 < alpha < 0.5:
        raise ConfigError(f"--alpha must lie in (0, 0.5), got {alpha}")
    fs = records[0].fs
    for r in records:
        r.require_output()
        if r.u.ndim != 1 or r.y.ndim != 1:
            raise ConfigError(f"{r.source}: bla handles one input and one output")
        if abs(r.fs - fs) > 1e-9 * fs:
            raise ConfigError(f"{r.source}: fs {r.fs:g} Hz differs from {records[0].source} ({fs:g} Hz)")
        if len(r) != len(records[0]):
            raise ConfigError(f"{r.source}: {len(r)} samples, {records[0].source} has {len(records[0])}")
    lines = None
    if len(records[0]) % periods == 0:
        found = [excited_from_meta(r, len(r) // periods) for r in records]
        if all(x is not None for x in found):
            lines = found
    return best_linear_approximation(
        [(r.u, r.y) for r in records], fs, periods, drop=drop, lines=lines, alpha=alpha, detrend=detrend
    )


def to_json(res) -> dict[str, Any]:
    nl = {k: v for k, v in res.nonlinearity.items()}
    return {
        "f_hz": res.f_hz,
        "re": res.G.real,
        "im": res.G.imag,
        "var_noise": res.var_noise,
        "var_distortion": res.var_distortion,
        "var_total": res.var_total,
        "nonlinearity": nl,
        "info": dict(res.info),
    }


def sentence(nl: dict[str, Any]) -> str:
    """One line such as ``odd nonlinear distortion 23.1 dB above noise; even: none (0.2 dB)``."""
    parts = []
    both = not nl.get("classified", True)
    for kind in ("odd", "even") if not both else ("odd",):
        lvl = nl.get(f"{kind}_db")
        name = kind if not both else "odd or even"
        if lvl is None:
            parts.append(f"{name}: no detection lines")
        elif nl.get(f"{kind}_detected"):
            parts.append(f"{name} nonlinear distortion {lvl:.1f} dB above noise")
        else:
            parts.append(f"{name}: none detected ({lvl:.1f} dB, threshold {nl.get(f'{kind}_threshold_db'):.1f} dB)")
    return f"verdict {nl['verdict']}: " + "; ".join(parts)


def run(args: argparse.Namespace) -> int:
    records = [read_data(args, f) for f in args.files]
    res = estimate(records, args.periods, args.drop, args.alpha, args.detrend)
    payload = to_json(res)
    if args.output:
        write_csv(
            {k: payload[k] for k in ("f_hz", "re", "im", "var_noise", "var_distortion", "var_total")}, args.output
        )
    if args.plot:
        from sysid.report.plots import plot_bla

        rec = records[0]
        unit = f"{rec.units.get('y', '')}/{rec.units.get('u', '')}" if rec.units.get("y") else ""
        plot_bla(
            res, args.plot, title=f"BLA of {len(records)} realisation(s), {res.info['periods_used']} periods", unit=unit
        )
    if args.json:
        emit_json({"files": list(args.files), **payload})
        return 0
    nl = res.nonlinearity
    info = res.info
    print(
        f"BLA: {info['realisations']} realisation(s) x {info['periods_used']} periods, {res.f_hz.size} excited "
        f"lines {res.f_hz[0]:g} .. {res.f_hz[-1]:g} Hz"
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        g2 = np.mean(np.abs(res.G) ** 2)
        snr = 10 * np.log10(g2 / np.nanmean(res.var_noise))
        print(f"noise level of G_BLA: {snr:.1f} dB below |G_BLA|")
        if np.isfinite(res.var_distortion).any():
            print(
                f"distortion level of G_BLA: {10 * np.log10(g2 / np.nanmean(res.var_distortion)):.1f} dB below |G_BLA|"
            )
    print(sentence(nl))
    for note in nl.get("notes", []):
        print(f"note: {note}")
    for what, path in (("csv", args.output), ("figure", args.plot)):
        if path:
            print(f"{what} -> {path}")
    return 0
