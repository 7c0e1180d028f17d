"""A throw-away PostgreSQL server for tests: its own cluster in a temporary folder, listening
on 127.0.0.1 only, at a free port, stopped and deleted at the end of the session, however the
test process ends (a reaper, tests/reaper.py, stops it if the session's end never runs).

`make test` installs Debian's postgresql package (scripts/system-deps.sh); the server is run as
the `postgres` user when the tests run as root, because PostgreSQL refuses to run as root.
"""

from __future__ import annotations

import contextlib
import glob
import os
import shutil
import socket
import subprocess
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.reaper import Reaper

__all__ = ["PostgresServer", "postgres_server"]


def _bin_dir() -> Path:
    found = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    if found:
        return Path(found[-1]).parent
    initdb = shutil.which("initdb")
    if initdb:
        return Path(initdb).parent
    pytest.fail("PostgreSQL is not installed: run `make system-deps` (Debian package postgresql)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class PostgresServer:
    """One running cluster; `database()` gives each test an empty database of its own."""

    def __init__(self, bin_dir: Path, root: Path, port: int, as_user: list[str]) -> None:
        self.bin_dir, self.root, self.port, self._as_user = bin_dir, root, port, as_user
        self.reaper: Reaper | None = None
        """Stops the server if this process ends before the session's end does."""

    def command(self, tool: str, *args: str) -> list[str]:
        """One PostgreSQL tool's command line (as the postgres user when root)."""
        return [*self._as_user, str(self.bin_dir / tool), *args]

    def run(self, tool: str, *args: str) -> None:
        """Run one PostgreSQL tool (as the postgres user when root); raise with its stderr."""
        done = subprocess.run(
            self.command(tool, *args),
            capture_output=True,
            text=True,
            timeout=60,
            cwd=self.root,  # readable by the postgres user
        )
        if done.returncode != 0:
            raise RuntimeError(f"{tool} failed ({done.returncode}): {done.stderr or done.stdout}")

    def database(self) -> str:
        """Create an empty database; its SQLAlchemy async URL."""
        name = f"t_{uuid.uuid4().hex[:12]}"
        self.run("createdb", "-h", "127.0.0.1", "-p", str(self.port), "-U", "guidebot", name)
        return f"postgresql+asyncpg://guidebot@127.0.0.1:{self.port}/{name}"


@contextlib.contextmanager
def postgres_server() -> Iterator[PostgresServer]:
    bin_dir = _bin_dir()
    root = Path(tempfile.mkdtemp(prefix="guidebot-pg-"))
    as_user: list[str] = []
    if os.geteuid() == 0:
        shutil.chown(root, "postgres", "postgres")
        as_user = ["runuser", "-u", "postgres", "--"]
    server = PostgresServer(bin_dir, root, _free_port(), as_user)
    data, log = root / "data", root / "server.log"
    stop = ("pg_ctl", "-D", str(data), "-m", "immediate", "-w", "stop")
    server.reaper = reaper = Reaper([server.command(*stop), ["rm", "-rf", str(root)]])
    try:
        server.run("initdb", "-D", str(data), "-U", "guidebot", "-A", "trust", "--no-sync")
        options = f"-h 127.0.0.1 -p {server.port} -k {root} -c fsync=off"
        server.run("pg_ctl", "-D", str(data), "-l", str(log), "-o", options, "-w", "start")
        yield server
    finally:
        if (data / "postmaster.pid").exists():
            with contextlib.suppress(subprocess.SubprocessError):
                server.run(*stop)
        shutil.rmtree(root, ignore_errors=True)
        reaper.done()
