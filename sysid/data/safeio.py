"""Atomic, non-destructive output files: one helper used by every writer of the project, so that an interrupted
or failed write never leaves a half-written file and never overwrites an input.

Every file the project writes goes through :func:`atomic_path` (or the thin wrappers
:func:`atomic_write_text`, :func:`atomic_write_bytes`, :func:`save_figure`):

1. the target is checked *before* anything is written: not a folder, no parent that is a file, and not the
   same file as one of the inputs of the running command (compared by inode with :func:`os.path.samefile`,
   so a symlink or a second hard link to an input is caught as well as the same name);
2. the data go to a temporary file in the target's own folder (same file system, so the rename is atomic),
   which is flushed and ``fsync``-ed;
3. :func:`os.replace` moves it over the target in one step, and the folder entry is ``fsync``-ed.

If the writer raises — an error, a full disk, ``KeyboardInterrupt`` (SIGINT) or the exception the CLI's
SIGTERM handler raises — the temporary file is removed and an existing target is left exactly as it was:
a reader sees either the old file or the complete new one, never a fragment.

The CLI registers the files a command reads with :func:`protect_inputs`; library code may pass ``inputs=``.
Every refusal is a one-line :class:`~sysid.errors.DataError` naming the path.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path

from sysid.errors import DataError

__all__ = [
    "check_memory",
    "available_memory",
    "atomic_path",
    "atomic_write_text",
    "atomic_write_bytes",
    "save_figure",
    "check_output_path",
    "check_output_dir",
    "protect_inputs",
    "protected_inputs",
    "same_file",
]

_PROTECTED: list[str] = []  # input files of the running CLI command (set by protect_inputs)


def protect_inputs(paths: Iterable[str | os.PathLike | None]) -> None:
    """Declare the input files of the running command: no output may be the same file (by inode)."""
    _PROTECTED[:] = [os.fspath(p) for p in paths if p]


def protected_inputs() -> list[str]:
    return list(_PROTECTED)


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """True when both paths exist and are the same file (inode and device; symlinks resolved)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_output_path(path: str | os.PathLike, inputs: Iterable[str | os.PathLike] = ()) -> Path:
    """Refuse (one-line DataError) an output file name that cannot or must not be written; write nothing."""
    path = Path(path)
    if path.is_dir():
        raise DataError(f"{path}: is a directory, expected a file name to write")
    _check_parents(path)
    for src in [*_PROTECTED, *inputs]:
        if same_file(path, src):
            raise DataError(
                f"{path}: output is the same file as the input {src}; write to another name "
                "(the input is left untouched)"
            )
    return path


def check_output_dir(path: str | os.PathLike, inputs: Iterable[str | os.PathLike] = ()) -> Path:
    """Refuse an output folder that is an existing file or lies under a file; create nothing."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise DataError(f"{path}: is a file, expected a folder to write into")
    _check_parents(path)
    return path


def _check_parents(path: Path) -> None:
    parent = next((a for a in path.parents if a.exists()), None)
    if parent is not None and not parent.is_dir():
        raise DataError(f"{path}: cannot write: {parent} is a file, not a folder")


def available_memory() -> int:
    """Bytes of memory available to a new allocation (Linux ``MemAvailable``; else physical memory)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 2**40


def check_memory(n_values: float, what: str, copies: float = 4.0, itemsize: int = 8) -> None:
    """Refuse (one-line DataError with the estimate) a request for ``n_values`` float64 values that, with
    ``copies`` working arrays of that size, would not fit in the available memory; call before allocating."""
    need = float(n_values) * itemsize * copies
    avail = available_memory()
    if not need < avail:
        raise DataError(
            f"{what}: needs about {need / 2**30:.3g} GiB ({float(n_values):.3g} samples x {copies:g} "
            f"working copies x {itemsize} B), more than the {avail / 2**30:.3g} GiB of memory available; "
            "ask for fewer samples"
        )


def _umask_mode() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextmanager
def atomic_path(path: str | os.PathLike, inputs: Iterable[str | os.PathLike] = ()) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` to write; on success it replaces ``path`` atomically.

    The temporary name keeps the target's suffix (``.x.npz.tmp-abc.npz``) so that writers that choose the
    format by suffix (numpy, scipy, matplotlib) behave as for the target. On any exception (including
    KeyboardInterrupt / SystemExit) the temporary file is removed and the old ``path`` is untouched.
    OSError while writing becomes a one-line DataError naming ``path``.
    """
    path = check_output_path(path, inputs)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"{path}: cannot write ({exc.strerror or exc})") from None
    # The name is fixed before the file exists and the file is created inside the try: an interrupt
    # (SIGINT/SIGTERM raise in this process) that lands right after the creation still removes it.
    tmp = path.parent / f".{path.name}.tmp-{secrets.token_hex(8)}{path.suffix}"
    try:
        os.close(os.open(tmp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o600))
        yield tmp
        mode = path.stat().st_mode & 0o7777 if path.exists() else _umask_mode()
        os.chmod(tmp, mode)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except OSError as exc:
        _remove(tmp)
        raise DataError(f"{path}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        _remove(tmp)
        raise


def _remove(tmp: Path) -> None:
    try:
        tmp.unlink()
    except OSError:
        pass


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_text(
    path: str | os.PathLike, text: str, inputs: Iterable[str | os.PathLike] = (), encoding: str = "utf-8"
) -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_path`)."""
    with atomic_path(path, inputs) as tmp:
        with open(tmp, "w", encoding=encoding, newline="") as fh:
            fh.write(text)
    return Path(path)


def atomic_write_bytes(path: str | os.PathLike, data: bytes, inputs: Iterable[str | os.PathLike] = ()) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`)."""
    with atomic_path(path, inputs) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def save_figure(fig, path: str | os.PathLike, **kwargs) -> Path:
    """``fig.savefig(path, **kwargs)`` through :func:`atomic_path` (the format follows the suffix)."""
    path = Path(path)
    kwargs.setdefault("format", path.suffix.lstrip(".") or None)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, **kwargs)
    return path
