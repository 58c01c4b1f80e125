"""``piezotwin diagnose TWIN --data FILE [--val FILE] [--params FILE] [--effects LIST] [--json] [--report DIR]``,
``piezotwin diagnose --fmu MODEL.fmu --data FILE [--param NAME ...]`` and ``piezotwin diagnose --model model.py ...``.

Calibrates the twin's configuration to the data, analyses the residual, names the cause among the twin's
catalog effects, extends the twin with it and reports the validation gain (library:
:func:`twins.discrepancy.run_diagnosis`). A user's FMU or Python model is wrapped in the generic effects
(:mod:`twins.external`).
"""

from __future__ import annotations

import argparse
import sys

from benchmarks.cli.common import (
    NONNEG_INT,
    add_data_args,
    add_twin_args,
    emit_json,
    number,
    read_data,
    same_fs,
    twin_from_args,
)
from sysid.data.safeio import check_output_path
from sysid.errors import ConfigError


def register(sub) -> None:
    p = sub.add_parser("diagnose", help="what a twin gets wrong about measured data, why, and the gain once modelled")
    p.add_argument("twin", nargs="?", help="a shipped twin (or give --fmu / --model)")
    p.add_argument(
        "--fmu", metavar="MODEL.fmu", help="diagnose this FMU (co-simulation or model exchange) instead of a twin"
    )
    p.add_argument(
        "--model",
        metavar="FILE.py[:NAME]",
        help="diagnose a Python model (Params dataclass + simulate or step; docs/diagnosis.md)",
    )
    p.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME",
        help="calibrate this parameter (may repeat; default: the twin's calibration parameters, for an "
        "FMU every Real parameter with declared min/max)",
    )
    p.add_argument(
        "--fmu-input", metavar="NAME", help="the FMU's input variable fed with the record's u (default: its only input)"
    )
    p.add_argument("--fmu-output", metavar="NAME", help="the FMU's output compared with y (default: its only output)")
    p.add_argument(
        "--fmu-effect",
        action="append",
        default=[],
        metavar="ID=P1,P2",
        help="an effect the FMU models itself, switched by its Boolean parameter effect_ID (or ID), with the ranged "
        "Real parameters it fits (may repeat); tried beside the generic effects",
    )
    p.add_argument("--data", required=True, metavar="FILE", help="measured (estimation) record")
    p.add_argument("--val", metavar="FILE", help="validation record (default: last 40 %% of --data)")
    p.add_argument(
        "--max-rounds",
        type=number(0, 100, integer=True),
        default=3,
        help="at most this many effects are added (default 3)",
    )
    p.add_argument("--candidates", metavar="LIST", help="comma-separated catalog effects to try (default: all missing)")
    p.add_argument("--no-calibrate", action="store_true", help="do not re-fit the starting configuration")
    p.add_argument("--skip", type=NONNEG_INT, default=0, help="leading samples not scored (initial transient)")
    p.add_argument(
        "--validation-start",
        default="given",
        metavar="HOW",
        help="the state a separate validation record starts in (a remanent state): 'given' as configured "
        "(default), 'fitted' on that record, or 'estimation': the estimation record's fitted start",
    )
    p.add_argument(
        "--starts",
        type=number(1, 20, integer=True),
        default=1,
        help="refit every candidate with the core from N starts spread over its parameters' ranges (default 1: "
        "only the best first-stage fits are refitted); for models that simulate in milliseconds",
    )
    p.add_argument(
        "--pairs",
        action="store_true",
        default=None,
        help="when a round's leader is not significant alone, try it jointly with each other candidate (two effects "
        "that mask each other; default: for a model given by its equations, a leader that lowers the validation NRMSE "
        "by 5 %% or more)",
    )
    p.add_argument(
        "--no-pairs",
        dest="pairs",
        action="store_false",
        help="never try a round's leader jointly with the others",
    )
    p.add_argument(
        "--trial-nfev",
        type=number(1, 10000, integer=True),
        default=25,
        help="least-squares evaluations of each full trial fit (default 25)",
    )
    add_data_args(p)
    add_twin_args(p)
    p.add_argument(
        "--progress",
        action="store_true",
        help="print the steps as they run on stderr (default when stderr is a terminal)",
    )
    p.add_argument("--json", action="store_true")
    p.add_argument("--report", metavar="DIR", help="write figures and index.html here")
    p.add_argument(
        "--save-hybrid",
        metavar="FILE.json",
        help="with an 'unexplained' verdict, save the hybrid twin (the extended twin plus its black-box remainder "
        "model) here; a shipped twin only",
    )
    p.add_argument(
        "--save-model",
        metavar="EXTENDED.py",
        help="with --model given by its equations (STATES, rates, output): write the extended model (calibrated, with "
        "the mechanisms the diagnosis added) here as a Python model file",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from twins.discrepancy import DiagnoseOptions, run_diagnosis
    from twins.discrepancy.confidence import CONFIDENT
    from twins.discrepancy.hybrid import hybrid_text

    if args.max_rounds < 0:
        raise ConfigError(f"--max-rounds must be >= 0, got {args.max_rounds}")
    twin, label = _twin(args)
    save_hybrid = getattr(args, "save_hybrid", None)
    save_model = getattr(args, "save_model", None)
    if save_model:
        if not hasattr(twin, "SPEC"):
            raise ConfigError(
                "--save-model: only a --model given by its equations (STATES, rates(x, u, p), output(x, u, p)) "
                "can be written back"
            )
        if not str(save_model).endswith(".py"):
            raise ConfigError(f"--save-model {save_model}: the extended model is a Python file; give a .py name")
        check_output_path(save_model, [args.data] + ([args.val] if args.val else []) + [args.model])
    if save_hybrid:
        if not args.twin:
            raise ConfigError("--save-hybrid: only the hybrid of a shipped twin can be saved (not of --fmu/--model)")
        check_output_path(save_hybrid, [args.data] + ([args.val] if args.val else []))
    data = read_data(args, args.data)
    val = read_data(args, args.val) if args.val else None
    same_fs([data] + ([val] if val is not None else []))
    cands = [c.strip() for c in args.candidates.split(",") if c.strip()] if args.candidates else None
    show = bool(getattr(args, "progress", False)) or sys.stderr.isatty()
    names = [n.strip() for item in args.param for n in str(item).split(",") if n.strip()] or None
    opts = DiagnoseOptions(
        candidates=cands,
        calibrate_baseline=not args.no_calibrate,
        skip=args.skip,
        calibration_params=names,
        starts=args.starts,
        pairs=args.pairs,
        trial_nfev=args.trial_nfev,
        validation_start=args.validation_start,
        progress=(lambda msg: print(f"[diagnose] {msg}", file=sys.stderr, flush=True)) if show else None,
        on_round=None if args.quiet else (lambda msg: print(f"[diagnose] {msg}", file=sys.stderr, flush=True)),
    )
    diagnosis = run_diagnosis(twin, data, val, max_rounds=args.max_rounds, options=opts)
    result = diagnosis.to_dict()
    if save_hybrid:
        if diagnosis.hybrid_twin is not None:
            result["hybrid"]["saved"] = str(diagnosis.hybrid_twin.save(save_hybrid))
        else:
            result.setdefault("hybrid", {})["saved"] = None
    if save_model:
        result["saved_model"] = str(_save_model(diagnosis, result, save_model))
    if args.report:
        from twins.discrepancy.report import write_report

        result["report"] = str(write_report(diagnosis.to_dict(keep_stages=True), args.report))
    if args.json:
        emit_json(result)
        return 0
    b, e = result["baseline"], result["extended"]
    print(f"diagnose {label}: verdict {result['verdict']}")
    if result.get("split", {}).get("note"):
        print(f"  validation: {result['split']['note']}")
    for note in result.get("ranges", []):
        print(f"  range: {note}")
    print(
        f"  validation NRMSE {b['nrmse_val']:.5g} -> {e['nrmse_val']:.5g} (ratio {result['gain']['nrmse_ratio']:.3f}),"
        f" R2 {b['r2_val']:.5f} -> {e['r2_val']:.5f}"
    )
    print(
        f"  correlation tests {'pass' if b['tests']['passed'] else 'fail'} -> "
        f"{'pass' if e['tests']['passed'] else 'fail'}"
    )
    for c in result["causes"]:
        params = ", ".join(
            f"{k}={v:.4g}" if isinstance(v, (int, float)) else f"{k}={v}" for k, v in c.get("params", {}).items()
        )
        print(f"  cause {c['effect']} (confidence {c['confidence']:.2f}) {params}")
        print(f"    {c['evidence']}")
    if result["verdict"] == "unexplained":
        rvn = result["residual_vs_noise"]
        if rvn.get("outside", True):
            print(f"  {rvn['text']}")
        else:  # attributed to no cause (twins.discrepancy.confidence.attributed_verdict)
            print(
                f"  no cause stated: the candidates above fit (residual {rvn['excess_ratio']:.3g}x the noise power) "
                f"but none states a confidence of {CONFIDENT}; the mechanism may lie outside the catalog"
            )
    if result.get("hybrid", {}).get("fitted") is not None:
        print(f"  {hybrid_text(result['hybrid'])}")
    sparse = result.get("sparse_term") or {}
    if sparse.get("fitted"):
        print(
            f"  sparse term inside the equations ({'significant' if sparse['significant'] else 'not significant'}, "
            f"p = {sparse['p_value']:.2g}): {sparse['text']}"
        )
    if save_model:
        print(f"  extended model -> {result['saved_model']}")
    if save_hybrid:
        saved = result["hybrid"].get("saved")
        print(
            f"  hybrid twin -> {saved}"
            if saved
            else f"  no hybrid twin saved: the verdict is {result['verdict']} "
            "(the hybrid is fitted when the residual stays far above the noise)"
        )
    elif not result["causes"]:
        print(f"  residual: {result['unexplained']['description']}")
    for row in result.get("at_bound", []):
        print(f"  at bound: {row['param']}={row['value']:.4g} {row['unit']} (its {row['side']} bound {row['bound']:g})")
    if args.report:
        print(f"  report -> {result['report']}")
    return 0


def _save_model(diagnosis, result: dict, path: str):
    """Write the diagnosis's final configuration as a Python model (:func:`twins.equations.writer.write_model`)."""
    from twins.equations.writer import write_model

    b, e = result["baseline"], result["extended"]
    named = [c["effect"] for c in result["causes"] if c["effect"] != "unexplained"]
    summary = (
        f"Verdict {result['verdict']}; causes named: {', '.join(named) or 'none'}. Validation NRMSE "
        f"{b['nrmse_val']:.4g} (calibrated as given) -> {e['nrmse_val']:.4g} (this model)."
    )
    sparse = result.get("sparse_term") or {}
    term = diagnosis.sparse_model if sparse.get("significant") else None
    if term is not None:
        summary += (
            f" The sparse term (no catalog mechanism has its form; added to {sparse['added_to']}) takes the validation "
            f"NRMSE to {sparse['nrmse_val_after']:.4g}."
        )
    twin = diagnosis.extended.twin
    if term is not None and sparse.get("added_to") != "the final configuration":
        twin = diagnosis.baseline.twin
    return write_model(twin, path, summary, term, sparse.get("text", ""))


def _twin(args: argparse.Namespace):
    """The twin to diagnose (a shipped one, an FMU or a Python model) and how to name it in the output."""
    given = [n for n, v in (("TWIN", args.twin), ("--fmu", args.fmu), ("--model", args.model)) if v]
    if len(given) != 1:
        raise ConfigError(
            "diagnose: give exactly one of TWIN, --fmu MODEL.fmu or --model FILE.py"
            + (f" (got {', '.join(given)})" if given else "")
        )
    if (args.fmu_input or args.fmu_output or args.fmu_effect) and not args.fmu:
        raise ConfigError("diagnose: --fmu-input/--fmu-output/--fmu-effect go with --fmu")
    if args.twin:
        return twin_from_args(args.twin, args), args.twin
    if args.fmu:
        from twins.external import fmu_twin_class

        names = [n.strip() for item in args.param for n in str(item).split(",") if n.strip()] or None
        cls = fmu_twin_class(args.fmu, names, args.fmu_input, args.fmu_output, _fmu_effects(args.fmu_effect))
        label = args.fmu
    else:
        from twins.external import load_model

        cls = load_model(args.model)
        label = args.model
    twin = cls.from_options(
        params_file=args.params,
        set_=args.set_,
        effect=args.effect,
        without=args.without,
        effects=args.effects,
        seed=getattr(args, "seed", 0),
    )
    return twin, label


def _fmu_effects(items: list[str]) -> dict[str, list[str]] | None:
    """``--fmu-effect ID=P1,P2`` items as {id: [parameters]}; a malformed one is refused with one line."""
    out: dict[str, list[str]] = {}
    for item in items:
        eid, sep, rest = str(item).partition("=")
        names = [n.strip() for n in rest.split(",") if n.strip()]
        if not sep or not eid.strip() or not names:
            raise ConfigError(f"--fmu-effect {item!r}: expected ID=PARAM[,PARAM...]")
        out[eid.strip()] = names
    return out or None
