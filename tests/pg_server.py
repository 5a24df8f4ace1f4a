"""A PostgreSQL server of the tests' own (Debian's ``postgresql``: ``.ci/run`` installs it), started in a temporary
folder on a free port of 127.0.0.1 and stopped at the end of the session. PostgreSQL refuses to run as root: as
root the server runs as ``nobody`` (through ``su``), in a folder given to it. Without PostgreSQL the tests that need
it skip, except in CI (``CI`` set), where they fail."""

from __future__ import annotations

import glob
import os
import shutil
import socket
import subprocess
import tempfile

import pytest

TIMEOUT_S = 60


def _bin(name: str) -> str | None:
    found = sorted(glob.glob(f"/usr/lib/postgresql/*/bin/{name}"))
    return found[-1] if found else shutil.which(name)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _missing(why: str):
    if os.environ.get("CI"):
        pytest.fail(f"CI installs postgresql and psycopg: {why}")
    pytest.skip(why)


class Server:
    """initdb, pg_ctl start; ``url`` for SQLAlchemy; :meth:`database` makes a fresh database."""

    def __init__(self):
        initdb, pg_ctl = _bin("initdb"), _bin("pg_ctl")
        if not initdb or not pg_ctl:
            _missing("PostgreSQL's initdb and pg_ctl are not installed (apt-get install postgresql)")
        try:
            import psycopg  # noqa: F401
        except ImportError:
            _missing("psycopg is not installed (pip install -e '.[fleet]')")
        self.pg_ctl = pg_ctl
        self.folder = tempfile.mkdtemp(prefix="lf-pg-", dir="/tmp")
        self.as_root = os.geteuid() == 0
        if self.as_root:
            shutil.chown(self.folder, "nobody")
        self.data, self.port = os.path.join(self.folder, "data"), _free_port()
        self._run([initdb, "-D", self.data, "-U", "twin", "--auth=trust", "-E", "UTF8", "--no-sync"])
        self._run([pg_ctl, "-D", self.data, "-l", os.path.join(self.folder, "server.log"), "-w", "-t", str(TIMEOUT_S),
                   "-o", f"-k {self.folder} -p {self.port} -c listen_addresses=127.0.0.1 -c fsync=off", "start"])
        self.base = f"postgresql+psycopg://twin@127.0.0.1:{self.port}"
        self.count = 0

    def _run(self, argv: list[str]) -> None:
        if self.as_root:
            argv = ["su", "nobody", "-s", "/bin/sh", "-c", " ".join(f"'{a}'" for a in argv)]
        r = subprocess.run(argv, capture_output=True, text=True, timeout=TIMEOUT_S, cwd=self.folder)
        if r.returncode != 0:
            raise RuntimeError(f"{argv[-1] if self.as_root else argv[0]} failed: {r.stdout[-800:]}{r.stderr[-800:]}")

    def database(self) -> str:
        """A new, empty database's URL."""
        import psycopg

        self.count += 1
        name = f"history{self.count}"
        with psycopg.connect(f"host=127.0.0.1 port={self.port} user=twin dbname=postgres", autocommit=True) as c:
            c.execute(f"CREATE DATABASE {name}")
        return f"{self.base}/{name}"

    def stop(self) -> None:
        try:
            self._run([self.pg_ctl, "-D", self.data, "-m", "immediate", "-w", "stop"])
        finally:
            shutil.rmtree(self.folder, ignore_errors=True)


@pytest.fixture(scope="session")
def postgres():
    server = Server()
    yield server
    server.stop()
