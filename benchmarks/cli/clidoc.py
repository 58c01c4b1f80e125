"""Write the CLI reference (``docs/cli.md``) from the argument parser, so that it cannot drift.

``python -m benchmarks.cli.clidoc -o docs/cli.md`` (or ``make docs``) regenerates it;
``tests/test_docs.py`` fails while the committed file differs from what this module generates. The text
is built from the parser's actions, not from argparse's help formatter, so it does not depend on the
terminal width or on the Python version's help layout. Not a command (not in ``COMMAND_MODULES``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HEADER = (
    "<!-- Generated from the argument parser by `python -m benchmarks.cli.clidoc -o docs/cli.md` "
    "(`make docs`). Do not edit: tests/test_docs.py compares it with the parser. -->"
)
_COMMON = {"help", "version", "quiet", "verbose"}


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _help(action: argparse.Action, prog: str) -> str:
    text = action.help or ""
    if text == argparse.SUPPRESS:
        return ""
    if "%" in text:
        params = dict(vars(action), prog=prog)
        params = {k: getattr(v, "__name__", v) for k, v in params.items()}
        try:
            text = text % params
        except (KeyError, TypeError, ValueError):
            pass
    return text


def _names(action: argparse.Action) -> str:
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`"
    if action.nargs == 0:
        return ", ".join(f"`{o}`" for o in action.option_strings)
    metavar = action.metavar
    if metavar is None:
        metavar = "{" + ",".join(map(str, action.choices)) + "}" if action.choices else action.dest.upper()
    if isinstance(metavar, tuple):
        metavar = " ".join(metavar)
    if action.nargs in ("*", "+"):
        metavar += " ..."
    return ", ".join(f"`{o} {metavar}`" for o in action.option_strings)


def _default(action: argparse.Action) -> str:
    d = action.default
    if action.nargs == 0 or d is None or d is argparse.SUPPRESS or d == [] or d is False:
        return ""
    return f"`{d}`"


def _synopsis(prog: str, parser: argparse.ArgumentParser) -> str:
    parts = [prog]
    for a in parser._actions:
        if a.option_strings or isinstance(a, argparse._SubParsersAction):
            continue
        name = " ".join(a.metavar) if isinstance(a.metavar, tuple) else (a.metavar or a.dest)
        if a.choices and not a.metavar:
            name = "{" + ",".join(map(str, a.choices)) + "}"
        parts.append(f"[{name} ...]" if a.nargs in ("*", "?") else f"{name} ..." if a.nargs == "+" else name)
    if any(a.option_strings and a.dest not in _COMMON for a in parser._actions):
        parts.append("[options]")
    return " ".join(parts)


def _options_table(parser: argparse.ArgumentParser, prog: str, skip_common: bool = True) -> list[str]:
    out: list[str] = []
    for group in parser._action_groups:
        rows = []
        for a in group._group_actions:
            if isinstance(a, argparse._SubParsersAction) or (skip_common and a.dest in _COMMON):
                continue
            if a.help == argparse.SUPPRESS:
                continue
            choices = f" Choices: {', '.join(map(str, a.choices))}." if a.choices and not a.option_strings else ""
            rows.append(f"| {_names(a)} | {_default(a)} | {_cell(_help(a, prog) + choices)} |")
        if not rows:
            continue
        title = group.title or "options"
        title = {"positional arguments": "arguments", "optional arguments": "options"}.get(title, title)
        out += ["", f"*{title}*", "", "| argument | default | meaning |", "|---|---|---|", *rows]
    return out


def _subparsers(parser: argparse.ArgumentParser):
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            helps = {c.dest: c.help for c in a._choices_actions}
            for name, p in a.choices.items():
                yield name, p, helps.get(name) or p.description or ""


def generate() -> str:
    """The Markdown CLI reference for the parser of :func:`benchmarks.cli.build_parser`."""
    from benchmarks.cli import build_parser

    parser = build_parser()
    lines = [
        HEADER,
        "",
        "# CLI reference",
        "",
        _cell(parser.description or ""),
        "",
        "```",
        "piezotwin [--version] [-q | -v] COMMAND [options]",
        "```",
        "",
        "Every command also takes `-h/--help`, `--version` (print the version), `-q/--quiet` (only results on",
        "stdout: no progress bars, information or warnings) and `-v/--verbose` (debug messages), before or after",
        "the command name. Bad input exits with status 2 and one line on stderr.",
        "",
        "| command | what it does |",
        "|---|---|",
    ]
    commands = list(_subparsers(parser))
    for name, _, text in commands:
        lines.append(f"| [`{name}`](#piezotwin-{name}) | {_cell(text)} |")

    def emit(prog: str, p: argparse.ArgumentParser, text: str, level: int) -> None:
        lines.extend(["", f"{'#' * level} {prog}", ""])
        if text:
            lines.extend([_cell(text), ""])
        if p.description and p.description != text:
            lines.extend([_cell(p.description), ""])
        lines.extend(["```", _synopsis(prog, p), "```"])
        lines.extend(_options_table(p, prog))
        if p.epilog:
            lines.extend(["", _cell(p.epilog)])
        for sub_name, sub_p, sub_text in _subparsers(p):
            emit(f"{prog} {sub_name}", sub_p, sub_text, level + 1)

    for name, p, text in commands:
        emit(f"piezotwin {name}", p, text, 2)
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.cli.clidoc", description=__doc__.splitlines()[0])
    ap.add_argument("-o", "--output", metavar="FILE", help="write here (atomically) instead of stdout")
    args = ap.parse_args(argv)
    text = generate()
    if args.output:
        from sysid.data.io import output_file

        with output_file(args.output) as tmp:
            Path(tmp).write_text(text, encoding="utf-8")
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
