"""Where a result came from: package version, git commit, command line, data-file hashes, date, machine.

:func:`collect` gathers it once per report; :func:`html_block` (:func:`sysid.report.provenance_section`)
renders it as the ``<section id="provenance">`` that every HTML report ends with. Nothing here is required
to succeed: a field that cannot be found (no git, a record that came from memory) says so instead of failing
the report.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shlex
import subprocess
import sys
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from sysid.report.html import REPORT_CSS, provenance_section  # noqa: F401  (REPORT_CSS: importable from its old home)

__all__ = ["collect", "commit", "html_block", "file_sha256"]

_ROOT = Path(__file__).resolve().parents[2]  # the checkout: sysid/report/provenance.py


def file_sha256(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """SHA-256 of a file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(chunk), b""):
            h.update(block)
    return h.hexdigest()


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("piezotwin")
    except PackageNotFoundError:  # pragma: no cover - always installed by make/pip
        return "unknown (not installed)"


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(_ROOT), *args], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def commit() -> str:
    """The git commit of this checkout (with a note when tracked files are modified), or why there is none."""
    head = _git("rev-parse", "HEAD")
    if not head:
        return "unknown (not a git checkout)"
    return head + (" (with uncommitted changes)" if _git("status", "--porcelain", "--untracked-files=no") else "")


def collect(
    files: Iterable[str | os.PathLike] = (),
    records: Iterable[Any] = (),
    command: list[str] | None = None,
) -> dict[str, Any]:
    """Provenance of a run as a JSON-able dict.

    ``files``: data files read (hashed); ``records``: :class:`sysid.data.record.Record` objects whose ``source`` is
    a file (hashed too; a record built in memory is listed by its source name only); ``command``: the command
    line (default ``sys.argv``).
    """
    data = []
    seen: set[str] = set()
    paths = [Path(f) for f in files] + [Path(str(getattr(r, "source", ""))) for r in records]
    for p in paths:
        key = str(p)
        if not key or key in seen or key == ".":
            continue
        seen.add(key)
        if p.is_file():
            data.append({"file": key, "bytes": p.stat().st_size, "sha256": file_sha256(p)})
        else:
            data.append({"file": key, "bytes": None, "sha256": None})
    argv = list(sys.argv if command is None else command)
    if argv and Path(argv[0]).name == "piezotwin":
        argv[0] = "piezotwin"  # the console script, not its install path
    return {
        "package": "piezotwin",
        "version": _version(),
        "commit": commit(),
        "command": shlex.join(argv) if argv else "",
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": f"{platform.node()} — {platform.platform()}, {platform.machine()}, {os.cpu_count()} CPUs, "
        f"Python {platform.python_version()}",
        "data": data,
    }


def html_block(prov: dict[str, Any]) -> str:
    """The provenance as an HTML ``<section id="provenance">`` (rendered by the report module, where every
    page of HTML is built)."""
    return provenance_section(prov)
