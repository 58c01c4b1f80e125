"""``piezotwin orders IDENTIFIER --est FILE [--val FILE] [--grid 1-2-4-8] [--set k=v] [--json] [--plot PNG]``.

Delay estimate per input (:func:`sysid.linear.order.delay_estimate`) and an order table of a linear identifier (``arx``,
``armax``, ``oe``, ``bj``, ``n4sid``): per order n (every order option set to n) the parameter count, AIC and BIC
on the estimation data and the free-run R² / NRMSE on the validation data; ``--plot`` draws it.
JSON keys: ``identifier``, ``delay`` (samples per input), ``rows`` ([{order, n_parameters, aic, bic, val_r2,
val_nrmse}]), ``best`` ({``aic``, ``bic``, ``validation``}: the order each criterion picks).
"""

from __future__ import annotations

import argparse
import math

from benchmarks.cli.common import add_data_args, emit_json, read_data
from sysid.config import parse_assignments
from sysid.errors import ConfigError
from sysid.linear.order import delay_estimate, order_table, plot_order_table


def register(sub) -> None:
    p = sub.add_parser("orders", help="delay estimate and order-selection table of a linear identifier")
    p.add_argument("identifier", help="arx, armax, oe, bj or n4sid")
    p.add_argument("--est", required=True, metavar="FILE", help="estimation record")
    p.add_argument("--val", metavar="FILE", help="validation record (free-run R² per order)")
    p.add_argument("--grid", default="1-2-3-4-6-8-10-12", metavar="N-N-...", help="orders to try (dash-separated)")
    p.add_argument("--max-delay", type=int, default=30, help="largest delay considered [samples] (default 30)")
    p.add_argument(
        "--set",
        dest="set_",
        action="append",
        default=[],
        metavar="KEY=VALUE[,...]",
        help="further identifier options (e.g. nk=3); the order options are set by the grid",
    )
    add_data_args(p)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--plot", metavar="PNG", help="write the order-selection figure")
    p.set_defaults(func=run)


def _grid(text: str) -> list[int]:
    try:
        out = [int(v) for v in str(text).replace(",", "-").split("-") if v.strip()]
    except ValueError:
        raise ConfigError(f"--grid: expected dash-separated positive integers, got {text!r}") from None
    if not out or any(v < 1 for v in out):
        raise ConfigError(f"--grid: expected dash-separated positive integers, got {text!r}")
    return out


def run(args: argparse.Namespace) -> int:
    from sysid.config import coerce
    from sysid.registry import get_identifier

    est = read_data(args, args.est)
    val = read_data(args, args.val) if args.val else None
    grid = _grid(args.grid)
    if args.max_delay < 0:
        raise ConfigError(f"--max-delay must be >= 0, got {args.max_delay}")
    delay = delay_estimate(est, max_delay=args.max_delay)
    cls = get_identifier(args.identifier)
    raw = parse_assignments(args.set_)
    defaults = cls().get_params() if args.identifier in ("arx", "armax", "oe", "bj", "n4sid") else {}
    options = {k: coerce(v, defaults.get(k), k) for k, v in raw.items()}
    if args.identifier in ("arx", "armax", "oe", "bj") and "nk" not in options:
        options["nk"] = delay[0] if len(delay) == 1 else delay
    rows = order_table(args.identifier, est, val, grid, options)
    best = {}
    for key, sign in (("aic", 1), ("bic", 1), ("val_nrmse", 1)):
        ok = [r for r in rows if r.get(key) is not None and math.isfinite(r[key])]
        if ok:
            best["validation" if key == "val_nrmse" else key] = min(ok, key=lambda r: sign * r[key])["order"]
    out = {"identifier": args.identifier, "delay": delay, "rows": rows, "best": best}
    if args.plot:
        out["plot"] = str(plot_order_table(rows, args.plot, title=f"{args.identifier} order selection"))
    if args.json:
        emit_json(out)
        return 0
    print(f"{args.identifier}: delay estimate nk = {'-'.join(map(str, delay))} samples")
    print(f"  {'order':>5} {'params':>6} {'AIC':>12} {'BIC':>12} {'val R2':>9}")
    for r in rows:
        if "error" in r:
            print(f"  {r['order']:>5} failed: {r['error']}")
            continue
        fmt = lambda v, f: "-" if v is None or not math.isfinite(v) else format(v, f)  # noqa: E731
        print(
            f"  {r['order']:>5} {r['n_parameters']:>6} {fmt(r['aic'], '12.1f')} {fmt(r['bic'], '12.1f')} "
            f"{fmt(r.get('val_r2'), '9.5f')}"
        )
    print("  best: " + ", ".join(f"{k} -> {v}" for k, v in best.items()))
    if args.plot:
        print(f"  figure -> {out['plot']}")
    return 0
