"""The ``piezotwin`` command line: parses arguments, calls the library, prints.

Each command lives in its own module under :mod:`benchmarks.commands` with ``register(subparsers)`` and
``run(args) -> int``. Any :class:`sysid.errors.InputError` (bad file, unknown parameter, out-of-range value)
is printed as one line on stderr with exit status 2 — never a traceback; so is an OSError about a path the
user named (an output folder that is a file, no permission ...).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from sysid.errors import InputError

# Order is the order of `piezotwin --help`.
COMMAND_MODULES = (
    "list_cmd",
    "signal",
    "preprocess",
    "simulate",
    "calibrate",
    "identify",
    "orders",
    "search",
    "score",
    "diagnose",
    "sweep",
    "export_fmu",
    "run",
)


class _Parser(argparse.ArgumentParser):
    """argparse prints usage + message and exits 2 on bad arguments; keep that, but on one line."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="piezotwin", description="Digital twins and black-box identification of piezoelectric systems.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"benchmarks.commands.{name}")
        except ImportError as exc:
            if exc.name and exc.name.startswith("benchmarks.commands"):
                continue  # command not built yet
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("MPLBACKEND", "Agg")
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"piezotwin {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 0
    except OSError as exc:  # a file or folder the user named cannot be read or written (plots, reports ...)
        if exc.filename is None:
            raise  # not about a path: a real fault, keep its traceback
        print(f"piezotwin {args.command}: error: {exc.filename}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"piezotwin {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
