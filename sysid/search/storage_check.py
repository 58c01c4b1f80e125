"""Validation and safe creation of a ``search --storage`` before any work, so that a bad path fails at once and
not after hours of training.

:func:`check_storage` turns the option into an Optuna storage URL (as :func:`sysid.search.storage_url`)
and refuses, with one line, what would otherwise be a traceback later: text that is not a URL, an unknown
database kind (``foo://``), a database whose Python driver is not installed (``postgresql://`` without
psycopg), an SQLite file in a folder that does not exist, or an existing file that is not an SQLite database
(a CSV given by mistake is never overwritten). :func:`init_sqlite` creates a new SQLite store's tables under
an exclusive file lock, so that two processes started at once on a new store do not both try to create it.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sysid.errors import ConfigError

__all__ = ["check_storage", "init_sqlite", "sqlite_path"]

SQLITE_MAGIC = b"SQLite format 3\x00"


def sqlite_path(url: str) -> Path | None:
    """The database file of an ``sqlite:///`` URL (None for other URLs and in-memory databases)."""
    from sqlalchemy.engine import make_url

    u = make_url(url)
    if not u.drivername.startswith("sqlite") or not u.database or u.database == ":memory:":
        return None
    return Path(u.database)


def check_storage(storage: str | None, study: str) -> str:
    """The storage URL for ``--storage`` / ``--study``, or a one-line ConfigError; creates nothing."""
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError, NoSuchModuleError

    from sysid.search import storage_url

    shown = storage if storage else f"{study}.db"
    if storage is not None and (not storage.strip() or any(c.isspace() for c in storage.split("://")[0])):
        raise ConfigError(f"--storage {storage!r}: not a file name or database URL")
    url = storage_url(storage, study)
    try:
        u = make_url(url)
    except ArgumentError:
        raise ConfigError(
            f"--storage {shown!r}: not a database URL (expected e.g. sqlite:///file.db, "
            "postgresql://user:pw@host/db, or a file name)"
        ) from None
    try:
        dialect = u.get_dialect()
    except NoSuchModuleError:
        raise ConfigError(
            f"--storage {shown!r}: unknown database kind {u.drivername!r} (sqlite, postgresql, mysql ...)"
        ) from None
    try:
        dialect.import_dbapi()
    except ImportError as exc:
        raise ConfigError(
            f"--storage {shown!r}: the Python driver for {u.drivername} is not installed "
            f"({exc.name or exc}); install it or use an SQLite file"
        ) from None
    path = sqlite_path(url)
    if path is not None:
        if not path.parent.is_dir():
            raise ConfigError(f"--storage {shown!r}: folder {path.parent} does not exist")
        if path.is_dir():
            raise ConfigError(f"--storage {shown!r}: is a folder, expected an SQLite file")
        if path.exists() and path.stat().st_size > 0:
            with open(path, "rb") as fh:
                if fh.read(16) != SQLITE_MAGIC:
                    raise ConfigError(
                        f"--storage {shown!r}: exists and is not an SQLite database; refusing to use (and overwrite) it"
                    )
    return url


@contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """Exclusive advisory lock on a folder (flock on its descriptor: no lock file is left behind)."""
    import fcntl

    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


def init_sqlite(url: str, open_storage) -> None:
    """Open the store once before the work: a new SQLite store's tables are created under an exclusive lock
    on its folder, so that concurrent first openers wait instead of racing on ``CREATE TABLE``; a database
    that cannot be reached (server down, wrong password) is a one-line ConfigError.
    ``open_storage(url)`` opens (and thereby initialises) the store."""
    from sqlalchemy.exc import SQLAlchemyError

    path = sqlite_path(url)
    try:
        if path is None:
            open_storage(url)
        elif not (path.exists() and path.stat().st_size > 0):
            with _locked(path.parent):
                open_storage(url)
    except SQLAlchemyError as exc:
        msg = str(getattr(exc, "orig", None) or exc).splitlines()[0][:200]
        raise ConfigError(f"--storage: cannot open the database ({type(exc).__name__}: {msg})") from None
