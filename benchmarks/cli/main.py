"""The ``piezotwin`` command line: parses arguments, calls the library, prints.

Each command lives in its own module under :mod:`benchmarks.cli` with ``register(subparsers)`` and
``run(args) -> int``. Any :class:`sysid.errors.InputError` (bad file, unknown parameter, out-of-range value)
is printed as one line on stderr with exit status 2 — never a traceback; so is an OSError about a path the
user named (an output folder that is a file, no permission ...).

Conventions of every command: ``--version``; ``-q/--quiet`` (only results on stdout: no
information messages, no progress bars, no warnings) and ``-v/--verbose`` (debug messages). The library logs
through :mod:`logging` and never configures it; this module does, for the duration of one command, and puts
it back afterwards. Python warnings are shown as one line each on stderr.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
import warnings

from sysid.errors import InputError

# Order is the order of `piezotwin --help`.
COMMAND_MODULES = (
    "list_cmd",
    "signal",
    "preprocess",
    "simulate",
    "calibrate",
    "identify",
    "frf",
    "bla",
    "predict",
    "compare",
    "orders",
    "search",
    "score",
    "records",
    "thesis",
    "diagnose",
    "bench_diagnosis",
    "sweep",
    "export_fmu",
    "run",
)


class _Parser(argparse.ArgumentParser):
    """argparse prints usage + message and exits 2 on bad arguments; keep that, but on one line."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


# Our packages: their loggers get the level the user asked for; everything else stays at WARNING.
_PACKAGES = ("sysid", "twins", "benchmarks")


def version() -> str:
    """The installed distribution's version (``0+unknown`` when running from a tree that is not installed)."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as _dist_version

    try:
        return _dist_version("piezotwin")
    except PackageNotFoundError:  # pragma: no cover - always installed by make/pip
        return "0+unknown"


def _add_common(p: argparse.ArgumentParser, top: bool) -> None:
    """``--version``, ``-q``, ``-v`` on the top-level parser and on every command.

    On the commands the defaults are suppressed so that ``piezotwin -q score`` and ``piezotwin score -q``
    both work (a sub-parser default would overwrite the top-level value).
    """
    g = p.add_argument_group("output") if not top else p
    g.add_argument("--version", action="version", version=f"piezotwin {version()}", help="print the version and exit")
    default = {} if top else {"default": argparse.SUPPRESS}
    g.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="print only results: no progress, information or warnings",
        **({"default": False} if top else default),
    )
    g.add_argument(
        "-v", "--verbose", action="count", help="more messages (debug)", **({"default": 0} if top else default)
    )


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="piezotwin", description="Digital twins and black-box identification of piezoelectric systems."
    )
    _add_common(parser, top=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"benchmarks.cli.{name}")
        except ImportError as exc:
            if exc.name and exc.name.startswith("benchmarks.cli"):
                continue  # command not built yet
            raise
        module.register(sub)
    for cmd in sub.choices.values():
        _add_common(cmd, top=False)
    return parser


class _Formatter(logging.Formatter):
    """Information as it is; warnings and errors prefixed with their level, one line."""

    def format(self, record: logging.LogRecord) -> str:
        msg = super().format(record)
        return msg if record.levelno < logging.WARNING else f"{record.levelname.lower()}: {msg}"


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is at the time of the message (tests replace it)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    text = str(message).strip().splitlines()[0] if str(message).strip() else category.__name__
    logging.getLogger("py.warnings").warning("%s: %s", category.__name__, text)


class _Session:
    """Logging, warnings and progress set up for one command, restored afterwards."""

    def __init__(self, quiet: bool, verbose: int) -> None:
        self.level = logging.ERROR if quiet else (logging.DEBUG if verbose else logging.INFO)
        self.quiet = quiet

    def __enter__(self) -> _Session:
        from sysid.progress import set_enabled

        root = logging.getLogger()
        self.handler = _StderrHandler()
        self.handler.setFormatter(_Formatter("%(message)s"))
        self.saved = {"root": root.level, **{p: logging.getLogger(p).level for p in _PACKAGES}}
        root.addHandler(self.handler)
        root.setLevel(logging.ERROR if self.quiet else logging.WARNING)
        for p in _PACKAGES:
            logging.getLogger(p).setLevel(self.level)
        self.showwarning = warnings.showwarning
        warnings.showwarning = _one_line_warning
        self.progress = set_enabled(not self.quiet)
        return self

    def __exit__(self, *exc) -> None:
        from sysid.progress import set_enabled

        root = logging.getLogger()
        root.removeHandler(self.handler)
        root.setLevel(self.saved["root"])
        for p in _PACKAGES:
            logging.getLogger(p).setLevel(self.saved[p])
        warnings.showwarning = self.showwarning
        set_enabled(self.progress)


class Terminated(BaseException):
    """Raised by the SIGTERM handler so that every ``finally`` / cleanup runs (temporary files removed)."""


def _on_sigterm(signum, frame):  # pragma: no cover - exercised in a subprocess test
    raise Terminated()


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    with _Session(quiet=bool(args.quiet), verbose=int(args.verbose or 0)):
        return _run(args)


def _run(args: argparse.Namespace) -> int:
    import signal
    import threading

    from sysid.data.safeio import protect_inputs

    previous = None
    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        from benchmarks.cli.common import preflight

        preflight(args)
        return int(args.func(args) or 0)
    except Terminated:
        print(f"piezotwin {args.command}: terminated (SIGTERM); no partial output left", file=sys.stderr)
        return 143
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
    except MemoryError as exc:  # a request the guards did not foresee: still one line, nothing written
        print(
            f"piezotwin {args.command}: error: not enough memory for this request ({exc or 'MemoryError'});"
            " ask for fewer samples",
            file=sys.stderr,
        )
        return 2
    finally:
        protect_inputs([])
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
