"""The ``piezotwin`` command line, on top of everything else: :mod:`benchmarks.cli.main` parses the arguments
and dispatches to one module per command (each defines ``register(subparsers)`` and sets ``func`` on its
parser). Nothing in ``sysid``, ``twins`` or the benchmark library imports this package."""

from benchmarks.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
