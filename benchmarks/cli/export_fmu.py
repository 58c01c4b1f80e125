"""``piezotwin export-fmu TWIN [--set ...] [--effect ...] [--effects ...] [--params FILE] [--seed N] [-o FILE]``
``piezotwin export-fmu --model MODEL [-o FILE]`` and ``piezotwin export-fmu --hybrid FILE [-o FILE]``.

Builds an FMI 2.0 co-simulation FMU of the twin as configured (the same configuration options as
``simulate``); see :mod:`twins.fmu` and the README section "fmu". With ``--model`` it exports an identified
model instead (:mod:`twins.fmu.model_export`; docs/models-in-use.md); with ``--hybrid`` a hybrid twin saved by
``diagnose --save-hybrid`` (physics twin + fitted remainder, :mod:`twins.fmu.hybrid_export`).
"""

from __future__ import annotations

import argparse
import time

from benchmarks.cli.common import FS, add_twin_args, emit_json, twin_from_args


def register(sub) -> None:
    p = sub.add_parser("export-fmu", help="export a twin or an identified model as an FMI 2.0 co-simulation FMU")
    p.add_argument("twin", nargs="?", help="twin to export (or give --model)")
    p.add_argument(
        "--model",
        metavar="MODEL",
        help="export this identified model file (identify -o), or a Python model file given by its equations "
        "(diagnose --save-model; needs --fs), instead of a twin",
    )
    p.add_argument(
        "--hybrid",
        metavar="FILE",
        help="export this hybrid twin file (diagnose --save-hybrid: the twin "
        "plus its fitted remainder) instead of a twin",
    )
    add_twin_args(p)
    p.add_argument(
        "--fs",
        type=FS,
        default=None,
        help="sampling rate [Hz] = 1/communication step (default: the twin's rate, "
        "cantilever 10 kHz, acoustic 100 MHz)",
    )
    p.add_argument("-o", "--output", metavar="FILE", help="output .fmu (default fmus/TWIN.fmu)")
    p.add_argument("--no-validate", action="store_true", help="skip the fmpy validation of the written FMU")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    p.set_defaults(func=run)


def _export(export, what, out: str, args: argparse.Namespace):
    """``export(what, out, fs=args.fs)`` timed, then checked by ``fmpy validate`` unless ``--no-validate``:
    returns (path, seconds, problems)."""
    t0 = time.perf_counter()
    path = export(what, out, fs=args.fs)
    seconds = time.perf_counter() - t0
    problems = []
    if not args.no_validate:
        from fmpy.validation import validate_fmu

        problems = validate_fmu(str(path))
    return path, seconds, problems


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from sysid.errors import ConfigError
    from twins.fmu import export_fmu
    from twins.fmu.spec import fmu_variables

    if sum(x is not None for x in (args.twin, args.model, args.hybrid)) != 1:
        raise ConfigError("export-fmu: give a twin name or --model MODEL or --hybrid FILE (one of the three)")
    if args.model is not None:
        return _run_model(args)
    if args.hybrid is not None:
        return _run_hybrid(args)
    twin = twin_from_args(args.twin, args)
    if args.fs is not None and not args.fs > 0:
        raise ConfigError(f"--fs must be positive, got {args.fs}")
    out = args.output or f"fmus/{args.twin}.fmu"
    path, seconds, problems = _export(export_fmu, twin, out, args)
    import json
    import zipfile

    with zipfile.ZipFile(path) as z:
        cfg = json.loads(z.read("resources/piezotwin_fmu.json"))
    summary = {
        "twin": twin.name,
        "fmu": str(path),
        "bytes": Path(path).stat().st_size,
        "fs": cfg["fs"],
        "core": cfg["core"],
        "effects": sorted(twin.effects),
        "seed": twin.seed,
        "parameters": [v["name"] for v in fmu_variables(twin, cfg["fs"])],
        "validation_problems": problems,
        "build_seconds": round(seconds, 3),
    }
    if args.json:
        emit_json(summary)
    else:
        core = cfg["core"]["kind"]
        extra = ""
        if core == "response" and "accuracy" in cfg["core"]:
            acc = cfg["core"]["accuracy"]
            extra = (
                f", response core vs simulate: relative RMS {acc['relative_rms']:.1e} "
                f"(linear stage {acc['linear_relative_rms']:.1e}) on a {acc['signal']}"
            )
        print(
            f"exported {twin.name} ({', '.join(sorted(twin.effects)) or 'no effects'}; fs {cfg['fs']:g} Hz; "
            f"core {core}{extra}) -> {path} ({summary['bytes'] / 1e3:.0f} kB, "
            f"{'valid' if not problems else 'INVALID'})"
        )
    if problems:
        for p in problems:
            print(f"validation: {p}")
        return 1
    return 0


def _run_model(args: argparse.Namespace) -> int:
    from pathlib import Path

    from sysid.base import load_model
    from sysid.errors import ConfigError
    from twins.fmu.model_export import export_model_fmu

    if args.fs is not None and not args.fs > 0:
        raise ConfigError(f"--fs must be positive, got {args.fs}")
    if str(args.model).endswith(".py"):
        return _run_python_model(args)
    model = load_model(args.model)
    out = args.output or f"fmus/{Path(args.model).stem}.fmu"
    path, seconds, problems = _export(export_model_fmu, model, out, args)
    fs = args.fs or model.fs_
    summary = {
        "model": str(args.model),
        "identifier": model.name,
        "fmu": str(path),
        "bytes": Path(path).stat().st_size,
        "fs": fs,
        "validation_problems": problems,
        "build_seconds": round(seconds, 3),
    }
    return _finish(
        args,
        summary,
        f"exported {model.name} model {args.model} (fs {fs:g} Hz, step 1/fs) -> {path} "
        f"({summary['bytes'] / 1e3:.0f} kB, {'valid' if not problems else 'INVALID'})",
    )


def _run_python_model(args: argparse.Namespace) -> int:
    """A Python model file given by its equations (``diagnose --save-model`` writes one) as a twin FMU: the file
    travels in the FMU and is loaded there again (:mod:`twins.equations.loaded`)."""
    from pathlib import Path

    from sysid.errors import ConfigError
    from twins.external import load_model
    from twins.fmu import export_fmu

    if args.fs is None:
        raise ConfigError(f"export-fmu --model {args.model}: give the sampling rate with --fs (a model file has none)")
    cls = load_model(args.model)
    if not hasattr(cls, "SPEC"):
        raise ConfigError(
            f"export-fmu --model {args.model}: only a model given by its equations (STATES, rates, output) exports"
        )
    twin = cls.from_options(
        params_file=args.params, set_=args.set_, effect=args.effect, without=args.without, effects=args.effects
    )
    out = args.output or f"fmus/{Path(args.model).stem}.fmu"
    path, seconds, problems = _export(export_fmu, twin, out, args)
    summary = {
        "model": str(args.model),
        "twin": twin.name,
        "effects": sorted(twin.effects),
        "fmu": str(path),
        "bytes": Path(path).stat().st_size,
        "fs": float(args.fs),
        "validation_problems": problems,
        "build_seconds": round(seconds, 3),
    }
    return _finish(
        args,
        summary,
        f"exported model {args.model} (fs {args.fs:g} Hz, step 1/fs) -> {path} ({summary['bytes'] / 1e3:.0f} kB, "
        f"{'valid' if not problems else 'INVALID'})",
    )


def _run_hybrid(args: argparse.Namespace) -> int:
    from pathlib import Path

    from sysid.errors import ConfigError
    from twins.fmu.hybrid_export import export_hybrid_fmu
    from twins.hybrid import HybridTwin

    if args.fs is not None and not args.fs > 0:
        raise ConfigError(f"--fs must be positive, got {args.fs}")
    hybrid = HybridTwin.load(args.hybrid)
    out = args.output or f"fmus/{Path(args.hybrid).stem}.fmu"
    path, seconds, problems = _export(export_hybrid_fmu, hybrid, out, args)
    fs = args.fs or hybrid.fs_
    summary = {
        "hybrid": str(args.hybrid),
        "twin": hybrid.physics.name,
        "effects": sorted(hybrid.physics.effects),
        "identifier": hybrid.identifier_,
        "fmu": str(path),
        "bytes": Path(path).stat().st_size,
        "fs": fs,
        "validation_problems": problems,
        "build_seconds": round(seconds, 3),
    }
    return _finish(
        args,
        summary,
        f"exported hybrid twin {args.hybrid} ({hybrid.physics.name} + {hybrid.identifier_} "
        f"remainder; fs {fs:g} Hz, step 1/fs) -> {path} ({summary['bytes'] / 1e3:.0f} kB, "
        f"{'valid' if not problems else 'INVALID'})",
    )


def _finish(args: argparse.Namespace, summary: dict, line: str) -> int:
    """Print the export's JSON summary (``--json``) or its one line, then each validation problem; exit status 1
    when the FMU did not validate."""
    problems = summary["validation_problems"]
    if args.json:
        emit_json(summary)
    else:
        print(line)
    for p in problems:
        print(f"validation: {p}")
    return 1 if problems else 0
