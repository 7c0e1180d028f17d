"""A throw-away redis-server for tests: 127.0.0.1 only, a free port, no persistence, stopped at
the end, however the test process ends (a reaper, tests/reaper.py: its own process group is
killed). `make test` installs Debian's redis-server (scripts/system-deps.sh); without it the
tests that need it are skipped, saying why."""

from __future__ import annotations

import contextlib
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator

import pytest

from tests.reaper import Reaper

__all__ = ["RedisServer", "redis_server"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class RedisServer:
    def __init__(self, port: int, args: list[str], root: str) -> None:
        self.port, self.args, self.root = port, args, root
        self.process, self.reaper = self._launch()

    def _launch(self) -> tuple[subprocess.Popen[bytes], Reaper]:
        """redis-server in a process group of its own, and a reaper that kills that group
        (and deletes its folder) if this process ends before ``stop()``."""
        process = subprocess.Popen(
            self.args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
        )
        reaper = Reaper([["kill", "-s", "KILL", "--", f"-{process.pid}"], ["rm", "-rf", self.root]])
        return process, reaper

    def stop(self) -> None:
        """SIGKILL: the broker is gone (every connection to it drops)."""
        self.process.kill()
        self.process.wait(10)
        self.reaper.done()

    def start(self) -> None:
        """Start it again on the same port (empty: pub/sub keeps nothing)."""
        self.process, self.reaper = self._launch()
        _wait_ping(self.port, self.process)

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"


def _wait_ping(port: int, process: subprocess.Popen[bytes], timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"redis-server exited with {process.returncode}")
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 1) as s:
            s.sendall(b"PING\r\n")
            if s.recv(16).startswith(b"+PONG"):
                return
        time.sleep(0.05)
    raise RuntimeError(f"redis-server did not answer on port {port} within {timeout} s")


@contextlib.contextmanager
def redis_server() -> Iterator[RedisServer]:
    binary = shutil.which("redis-server")
    if binary is None:
        pytest.skip("redis-server is not installed: run `make system-deps` (Debian redis-server)")
    port = _free_port()
    with tempfile.TemporaryDirectory(prefix="guidebot-redis-") as root:
        args = [binary, "--bind", "127.0.0.1", "--port", str(port), "--save", ""]
        args += ["--appendonly", "no", "--dir", root, "--protected-mode", "no"]
        server = RedisServer(port, args, root)
        try:
            _wait_ping(port, server.process)
            yield server
        finally:
            server.stop()
