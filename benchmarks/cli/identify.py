"""``piezotwin identify IDENTIFIER --est FILE [--est FILE ...] [--val FILE] [--set k=v,...] [--json] [-o MODEL]``.

Generic over the identifier registry (:mod:`sysid.registry`): any registered identifier (linear, polynomial,
neural) is built with ``Identifier.from_assignments`` from the ``--set`` options, fitted on the estimation
record(s) (several ``--est`` files are separate experiments) and scored by
:func:`sysid.evaluation.evaluate.evaluate`; the
work is the library's :func:`sysid.identify.identify` (which also holds a nonlinear default against the linear
one and, with ``--set auto=true``, keeps the better).
The JSON keys are the contract of interfaces.md: ``identifier, params, n_parameters, fit_seconds, terms,
estimation: {one_step: {r2, nrmse}, free_run: {r2, nrmse}}, validation: {...}``.
Other commands and teams reuse :func:`sysid.identify.identify` (re-exported here as before).
"""

from __future__ import annotations

import argparse

from benchmarks.cli.common import add_data_args, add_set_arg, emit_json, read_data, same_fs
from sysid.config import parse_assignments
from sysid.identify import identify

__all__ = ["identify", "register", "run"]


def register(sub) -> None:
    p = sub.add_parser(
        "identify", help="identify a black-box model (arx, armax, oe, bj, n4sid, narx-poly, narmax-poly, ...)"
    )
    p.add_argument("identifier", help="identifier id (piezotwin list identifiers)")
    p.add_argument(
        "--est",
        required=True,
        action="append",
        metavar="FILE",
        help="estimation record; repeat for several separate experiments",
    )
    p.add_argument("--val", metavar="FILE", help="validation record")
    add_set_arg(
        p,
        "identifier options, e.g. ny=2,nu=2,degree=2,criterion=bic; may repeat. auto=true (nonlinear "
        "identifiers): also fit the default linear model (arx) and keep whichever simulates the hold-out "
        "(--val, else the last 30%% of the estimation data) better",
    )
    add_data_args(p)
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument(
        "-o",
        "--output",
        metavar="MODEL",
        help="save the fitted model: .npz (or .json, readable text); "
        "use it with predict / compare / export-fmu --model (docs/models-in-use.md)",
    )
    p.add_argument("--plots", metavar="DIR", help="write residual / correlation-test / scatter PNGs to DIR")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    est = [read_data(args, f) for f in args.est]
    val = read_data(args, args.val) if args.val else None
    same_fs(est + ([val] if val is not None else []))
    model, summary = identify(args.identifier, est if len(est) > 1 else est[0], val, parse_assignments(args.set_))
    if args.output:
        path = model.save(args.output)
        summary["model_file"] = str(path)
    if args.plots:
        from sysid.report.plots import identification_report

        summary["plots"] = identification_report(model, val if val is not None else est[0], args.plots)
        if hasattr(model, "simulation_band"):  # linear models with uncertainty
            from sysid.report.linplots import linear_report

            summary["plots"].update(linear_report(model, val if val is not None else est[0], args.plots))
    if args.json:
        emit_json(summary)
        return 0
    print(f"{summary['identifier']}: {summary['n_parameters']} parameters, fitted in {summary['fit_seconds']:.2f} s")
    if hasattr(model, "summary"):
        print(model.summary())
    if summary.get("chosen_orders"):
        print(
            "  orders chosen automatically (none given): "
            + ", ".join(
                f"{k}={'-'.join(map(str, v)) if isinstance(v, list) else v}"
                for k, v in summary["chosen_orders"].items()
            )
        )
    for part in ("estimation", "validation"):
        s = summary.get(part)
        if not s:
            continue
        for mode, m in s.items():
            r2 = "nan" if m["r2"] is None else f"{m['r2']:.5f}"
            nr = "nan" if m["nrmse"] is None else f"{m['nrmse']:.5f}"
            extra = f"  (diverged at sample {m['diverged_at']})" if "diverged_at" in m else ""
            print(f"  {part:<10} {mode:<8} R2 = {r2}  NRMSE = {nr}{extra}")
    ref = summary.get("linear_reference")
    if ref:
        print(
            f"  linear reference {ref['identifier']}: free-run R2 = {ref['r2']:.5f} on the {ref['holdout']} "
            f"({summary.get('fallback', {}).get('requested', summary['identifier'])}: {ref['model_r2']:.5f})"
        )
    if summary.get("fallback"):
        print(f"  auto=true: kept {summary['fallback']['kept']} instead of {summary['fallback']['requested']}")
    for w in summary.get("warnings", []):
        print(f"  warning: {w}")
    if args.output:
        print(f"  model -> {summary['model_file']}")
    return 0
