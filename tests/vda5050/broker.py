"""A throw-away Eclipse Mosquitto for tests: 127.0.0.1 only, a free port, no persistence,
stopped at the end. `make test` installs Debian's mosquitto (scripts/system-deps.sh); without it
the tests that need it are skipped, saying why."""

from __future__ import annotations

import contextlib
import shutil
import socket
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.netports import free_ports

__all__ = ["Mosquitto", "mosquitto"]


def _binary() -> str | None:
    return shutil.which("mosquitto") or shutil.which("mosquitto", path="/usr/sbin:/sbin")


class Mosquitto:
    def __init__(self, binary: str, port: int, config: Path) -> None:
        self.binary, self.port, self.config = binary, port, config
        self.process: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    def start(self) -> None:
        self.process = subprocess.Popen(
            [self.binary, "-c", str(self.config)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            if self.process.poll() is not None:
                raise RuntimeError(f"mosquitto exited with {self.process.returncode}")
            with (
                contextlib.suppress(OSError),
                socket.create_connection(("127.0.0.1", self.port), 1),
            ):
                return
            time.sleep(0.05)
        raise RuntimeError(f"mosquitto did not listen on port {self.port} within 20 s")

    def stop(self) -> None:
        """SIGKILL: the broker is gone (every connection to it drops)."""
        if self.process is not None:
            self.process.kill()
            self.process.wait(10)
            self.process = None


@contextlib.contextmanager
def mosquitto(*, started: bool = True) -> Iterator[Mosquitto]:
    """A private broker (``started=False``: configured, not running yet)."""
    binary = _binary()
    if binary is None:
        pytest.skip("mosquitto is not installed: run `make system-deps` (Debian mosquitto)")
    port = free_ports(1)[0]
    with tempfile.TemporaryDirectory(prefix="guidebot-mosquitto-") as root:
        config = Path(root) / "mosquitto.conf"
        config.write_text(
            f"listener {port} 127.0.0.1\nallow_anonymous true\npersistence false\nlog_dest none\n"
            "set_tcp_nodelay true\n",
            encoding="utf-8",
        )
        broker = Mosquitto(binary, port, config)
        if started:
            broker.start()
        try:
            yield broker
        finally:
            broker.stop()
