"""A real PostgreSQL server for the tests: initdb + pg_ctl into a temporary folder, on a free loopback port.

The server binaries come from Debian's ``postgresql`` package (``.ci/run`` installs it). PostgreSQL refuses
to run as root: under root the server runs as the ``postgres`` user the package creates. If the server cannot
be started the fixture FAILS with the reason (never a silent skip): the tests of shared Optuna studies are
about this server, not about a mock.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import pytest


def _bin(name: str) -> str | None:
    found = shutil.which(name)
    if found:
        return found
    cands = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"))
    return cands[-1] if cands else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PostgresServer:
    """``start()`` → URL ``postgresql+psycopg2://piezotwin@127.0.0.1:PORT/piezotwin``; ``stop()`` removes it."""

    def __init__(self):
        self.dir = Path(tempfile.mkdtemp(prefix="piezotwin-pg-"))  # not under pytest's 0700 tmp: postgres must enter
        self.port = _free_port()
        self.prefix: list[str] = []
        self.pg_ctl = _bin("pg_ctl")
        self.initdb = _bin("initdb")

    @property
    def url(self) -> str:
        return f"postgresql+psycopg2://piezotwin@127.0.0.1:{self.port}/piezotwin"

    def _run(self, cmd: list[str], timeout: float = 120) -> subprocess.CompletedProcess:
        return subprocess.run(self.prefix + cmd, capture_output=True, text=True, timeout=timeout)

    def start(self) -> str:
        if not (self.pg_ctl and self.initdb):
            raise RuntimeError("PostgreSQL server binaries (initdb, pg_ctl) not found: apt-get install postgresql")
        if os.geteuid() == 0:
            try:
                pw = pwd.getpwnam("postgres")
            except KeyError:
                raise RuntimeError("running as root and there is no 'postgres' user to run the server as") from None
            os.chown(self.dir, pw.pw_uid, pw.pw_gid)
            self.prefix = ["runuser", "-u", "postgres", "--"]
        data = self.dir / "data"
        r = self._run([self.initdb, "-D", str(data), "-U", "piezotwin", "--auth=trust", "-E", "UTF8", "--no-sync"])
        if r.returncode != 0:
            raise RuntimeError(f"initdb failed: {r.stderr.strip() or r.stdout.strip()}")
        opts = f"-c listen_addresses=127.0.0.1 -p {self.port} -k {self.dir} -c fsync=off -c max_connections=60"
        r = self._run(
            [self.pg_ctl, "-D", str(data), "-l", str(self.dir / "log"), "-o", opts, "-w", "-t", "60", "start"]
        )
        if r.returncode != 0:
            log = (self.dir / "log").read_text()[-800:] if (self.dir / "log").exists() else ""
            raise RuntimeError(f"pg_ctl start failed: {r.stderr.strip() or r.stdout.strip()} {log}")
        import psycopg2

        for _ in range(50):
            try:
                conn = psycopg2.connect(host="127.0.0.1", port=self.port, user="piezotwin", dbname="postgres")
                break
            except psycopg2.OperationalError:
                time.sleep(0.2)
        else:
            raise RuntimeError("PostgreSQL started but accepts no connection")
        conn.autocommit = True
        conn.cursor().execute("CREATE DATABASE piezotwin")
        conn.close()
        return self.url

    def stop(self) -> None:
        if self.pg_ctl and (self.dir / "data" / "postmaster.pid").exists():
            self._run([self.pg_ctl, "-D", str(self.dir / "data"), "-m", "immediate", "-w", "stop"], timeout=60)
        shutil.rmtree(self.dir, ignore_errors=True)


@pytest.fixture(scope="module")
def postgres_url():
    """URL of a fresh PostgreSQL database on a server started for this test module."""
    server = PostgresServer()
    try:
        url = server.start()
    except Exception as exc:
        server.stop()
        pytest.fail(f"PostgreSQL server could not be started: {exc}", pytrace=False)
    try:
        yield url
    finally:
        server.stop()
