"""The soak's fleet: building simulator, server and robot agents as separate processes on
loopback, each logging to its own file, killed and restarted at will; and a TCP relay per robot
between its link and the server, which the soak cuts to drop the robot's connection."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import socket
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx

from guidebot.processes import spawn_guidebot, stop_process

__all__ = ["Child", "LinkRelay", "free_port", "wait_for"]


def free_port() -> int:
    """A port free now (the server keeps it across its restarts)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def wait_for(what: str, predicate: object, timeout: float, period: float = 0.2) -> None:
    """Poll ``predicate`` (sync or async callable) until true; TimeoutError naming ``what``."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        result = predicate()  # type: ignore[operator]
        if asyncio.iscoroutine(result):
            result = await result
        if result:
            return
        await asyncio.sleep(period)
    raise TimeoutError(f"{what}: not within {timeout:g} s")


@dataclass
class Child:
    """One ``guidebot`` process; stdout and stderr go to ``log`` (appended over restarts)."""

    name: str
    args: list[str]
    log: Path
    env: dict[str, str] = field(default_factory=dict)
    process: subprocess.Popen[bytes] | None = None
    started_at_offset: int = 0
    restarts: int = 0

    def start(self) -> None:
        self.started_at_offset = self.log.stat().st_size if self.log.exists() else 0
        with self.log.open("ab") as out:
            self.process = spawn_guidebot(
                self.args,
                stdout=out,
                stderr=subprocess.STDOUT,
                env={**os.environ, "PYTHONUNBUFFERED": "1", **self.env},
            )

    @property
    def alive(self) -> bool:
        return self.process is not None and self.process.poll() is None

    @property
    def pid(self) -> int | None:
        return self.process.pid if self.alive and self.process else None

    def output(self) -> str:
        """What this incarnation wrote so far."""
        with self.log.open("rb") as f:
            f.seek(self.started_at_offset)
            return f.read().decode("utf-8", "replace")

    def kill(self) -> None:
        """SIGKILL: no clean-up at all, as a crash or a power cut."""
        if self.process is not None and self.process.poll() is None:
            self.process.send_signal(signal.SIGKILL)
            self.process.wait()

    def stop(self, grace_s: float = 10.0) -> None:
        """SIGTERM, then SIGKILL after ``grace_s``."""
        if self.process is not None:
            stop_process(self.process, grace_s)

    def restart(self) -> None:
        self.kill()
        self.restarts += 1
        self.start()

    def ready_json(self) -> dict[str, object] | None:
        """The building simulator's ``{"ready": true, ...}`` line, once printed."""
        for line in self.output().splitlines():
            if line.startswith("{") and '"ready"' in line:
                data = json.loads(line)
                if isinstance(data, dict):
                    return data
        return None


async def healthy(url: str) -> bool:
    try:
        async with httpx.AsyncClient(timeout=2.0) as http:
            return (await http.get(f"{url}/api/health")).status_code == 200
    except httpx.HTTPError:
        return False


class LinkRelay:
    """A TCP relay 127.0.0.1:port -> the server; ``cut`` drops every connection through it and
    refuses new ones until ``restore`` (a robot's Wi-Fi gone, then back). ``fallback_ports``:
    servers tried in turn when the target refuses a new connection, as a load balancer does
    when a server process died (tests/scale)."""

    def __init__(self, target_port: int, *fallback_ports: int) -> None:
        self.target_port = target_port
        self.fallback_ports = fallback_ports
        self.port = 0
        self.cut_now = False
        self._server: asyncio.Server | None = None
        self._writers: set[asyncio.StreamWriter] = set()
        self._tasks: set[asyncio.Task[None]] = set()

    async def start(self) -> None:
        self._server = await asyncio.start_server(self._accept, "127.0.0.1", 0)
        self.port = int(self._server.sockets[0].getsockname()[1])

    def cut(self) -> None:
        self.cut_now = True
        for writer in list(self._writers):
            writer.transport.abort()
        self._writers.clear()

    def restore(self) -> None:
        self.cut_now = False

    async def stop(self) -> None:
        self.cut()
        if self._server is not None:
            self._server.close()
            with contextlib.suppress(Exception):
                await self._server.wait_closed()
        for task in list(self._tasks):
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self.cut_now:
            writer.transport.abort()
            return
        for port in (self.target_port, *self.fallback_ports):
            try:
                up_reader, up_writer = await asyncio.open_connection("127.0.0.1", port)
                break
            except OSError:
                continue
        else:
            writer.transport.abort()
            return
        self._writers |= {writer, up_writer}
        pipes = [
            asyncio.create_task(self._pipe(reader, up_writer)),
            asyncio.create_task(self._pipe(up_reader, writer)),
        ]
        self._tasks.update(pipes)
        try:
            await asyncio.wait(pipes, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for w in (writer, up_writer):
                self._writers.discard(w)
                w.transport.abort()
            for pipe in pipes:
                pipe.cancel()
                self._tasks.discard(pipe)

    @staticmethod
    async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        with contextlib.suppress(OSError, asyncio.IncompleteReadError):
            while data := await reader.read(65536):
                writer.write(data)
                await writer.drain()
