"""``piezotwin predict MODEL --data FILE [--horizon 1|K|inf] [--json] [-o OUT]``.

Loads any saved model (:func:`sysid.base.load_model`: every identifier, every model-file version) and predicts
the data file one step ahead, K steps ahead (at every sample) or in free run. A free run needs only the input
``u`` (and ``t`` or ``--fs``); it then starts from zero initial conditions. With a measured ``y`` in the file the
fit is printed (NRMSE fit %, R², RMSE, after the model's ``max_lag`` initial samples) and the free run starts
from the measured initial conditions. Default horizon: 1 with ``y``, inf without. ``-o`` writes a record
(``.npz``/``.csv``/``.mat``) with the input and the prediction as ``y``, atomically.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from benchmarks.cli.common import add_data_args, emit_json, read_data
from sysid.base import load_model
from sysid.data.io import write_record
from sysid.data.modelfile import atomic_path
from sysid.errors import DataError
from sysid.report.compare import horizon_label, parse_horizon, predict_scores


def register(sub) -> None:
    p = sub.add_parser("predict", help="predict data with a saved model (one-step, K-step or free run)")
    p.add_argument("model", metavar="MODEL", help="model file written by identify -o")
    p.add_argument("--data", required=True, metavar="FILE", help="data record (.npz/.csv/.mat); y is optional")
    p.add_argument(
        "--horizon",
        default=None,
        metavar="1|K|inf",
        help="1 = one step, K = K steps ahead, inf = free-run simulation (default: 1 with y, inf without)",
    )
    add_data_args(p)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("-o", "--output", metavar="OUT", help="write input + prediction as a record (.npz/.csv/.mat)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    model = load_model(args.model)
    rec = read_data(args, args.data, require_y=False)
    if args.horizon is None:
        horizon = 1 if rec.y is not None else None
    else:
        horizon = parse_horizon(args.horizon)
    yh, summary = predict_scores(model, rec, horizon)
    summary = {
        "model": str(args.model),
        "identifier": model.name,
        "data": str(args.data),
        "n_samples": len(rec),
        "fs": rec.fs,
        **summary,
        "output": None,
    }
    finite = bool(np.isfinite(yh).all())
    if args.output:
        if not finite:
            raise DataError(
                f"{args.data}: the {horizon_label(horizon)} prediction diverged at sample "
                f"{summary['diverged_at']}; nothing written to {args.output}"
            )
        meta = {
            "prediction": {
                "model": Path(args.model).name,
                "identifier": model.name,
                "horizon": summary["horizon"],
                "initial_conditions": summary["initial_conditions"],
            },
            "provenance": {"file": Path(args.data).name},
        }
        units = dict(rec.units)
        est = getattr(model, "estimation_", None) or {}
        if not units.get("y") and est.get("units", {}).get("y"):
            units["y"] = est["units"]["y"]
        out = rec.replace(
            y=yh.reshape((len(rec),) if yh.ndim == 1 or yh.shape[1] == 1 else yh.shape), units=units, meta=meta
        )
        with atomic_path(args.output) as tmp:
            write_record(out, tmp)
        summary["output"] = str(args.output)
    if args.json:
        emit_json(summary)
        return 0
    line = f"{model.name} {horizon_label(horizon)} on {args.data} ({len(rec)} samples at {rec.fs:g} Hz"
    line += ", zero initial conditions)" if summary["initial_conditions"] == "zero" else ")"
    print(line)
    m = summary["metrics"]
    if m is not None:
        unit = rec.units.get("y", "")
        print(
            f"  fit {m['fit_percent']:.3f} %  R2 {m['r2']:.6f}  RMSE {m['rmse']:.6g}{' ' + unit if unit else ''}"
            f"  (after the first {summary['skip']} samples)"
        )
    if summary["diverged_at"] is not None:
        print(f"  diverged at sample {summary['diverged_at']}")
    if summary["output"]:
        print(f"  prediction -> {summary['output']}")
    return 0
