"""``piezotwin compare MODEL... --data FILE [--horizon 1|K|inf] [--fir-est FILE] [--json] [--report DIR]``.

The MATLAB ``compare`` of this tool: every model predicts the measured record (default: free run from the measured
initial conditions) and gets its NRMSE fit %, R² and RMSE, all on the same samples (after the largest ``max_lag`` of
the models). ``--fir-est FILE`` adds a reference row: the least-squares FIR of ``identify fir`` (taps chosen on a
hold-out of FILE), fitted on that estimation record (JSON row key ``reference: true``); as its max_lag is its tap
count, every model is then scored after it. ``--report DIR`` writes ``compare.png`` (measured vs predicted, whole
record and a zoom) and ``residual_tests_<i>.png`` (the correlation tests of eq. 2-32 on model i's one-step
residuals).
"""

from __future__ import annotations

import argparse
from typing import Any

from benchmarks.cli.common import add_data_args, emit_json, read_data, same_fs
from sysid.base import load_model
from sysid.report.compare import compare, compare_report, fir_reference, horizon_label, parse_horizon


def register(sub) -> None:
    p = sub.add_parser("compare", help="compare saved models on measured data (fit %%, R2, RMSE, figures)")
    p.add_argument("models", nargs="+", metavar="MODEL", help="model files written by identify -o")
    p.add_argument("--data", required=True, metavar="FILE", help="measured record (needs y)")
    p.add_argument(
        "--horizon",
        default="inf",
        metavar="1|K|inf",
        help="1 = one step, K = K steps ahead, inf = free-run simulation (default inf)",
    )
    p.add_argument(
        "--fir-est",
        metavar="FILE",
        help="also fit the least-squares FIR reference (identify fir, taps "
        "chosen on a hold-out) on this estimation record and show it beside the models",
    )
    add_data_args(p)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--report", metavar="DIR", help="write the figures to DIR")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    horizon = parse_horizon(args.horizon)
    models = [load_model(path) for path in args.models]
    rec = read_data(args, args.data, require_y=True)
    names = list(args.models)
    if args.fir_est:
        est = read_data(args, args.fir_est, require_y=True)
        same_fs([rec, est])
        models.append(fir_reference(est))
        names.append(f"fir (reference, {args.fir_est})")
    preds, rows = compare(models, rec, horizon, names=names)
    if args.fir_est:
        rows[-1]["reference"] = True
    result: dict[str, Any] = {
        "data": str(args.data),
        "n_samples": len(rec),
        "fs": rec.fs,
        "horizon": "inf" if horizon is None else horizon,
        "models": rows,
    }
    if args.report:
        result["report"] = compare_report(models, names, rec, preds, rows, args.report)
    if args.json:
        emit_json(result)
        return 0
    print(f"{horizon_label(horizon)} on {args.data} ({len(rec)} samples; scored after sample {rows[0]['skip']})")
    width = max(len(r["model"]) for r in rows)
    print(f"  {'model':<{width}}  {'identifier':<12} {'fit %':>9} {'R2':>10} {'RMSE':>11}")
    for r in rows:
        m = r["metrics"]
        extra = f"  diverged at sample {r['diverged_at']}" if r["diverged_at"] is not None else ""
        print(
            f"  {r['model']:<{width}}  {r['identifier']:<12} {m['fit_percent']:9.3f} {m['r2']:10.6f} "
            f"{m['rmse']:11.5g}{extra}"
        )
    if args.report:
        for key, path in result["report"]["files"].items():
            print(f"  {key} -> {path}")
    return 0
