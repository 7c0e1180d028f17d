"""Several real `guidebot server --broker` processes on loopback sharing one PostgreSQL
database and one Redis: for `guidebot bench failover` and the scale-out tests (tests/scale)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import socket
import ssl
import subprocess
import sys
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import httpx

__all__ = ["ADMIN_TOKEN", "DEMO", "GUI_TOKEN", "ServerProcess", "start_servers", "wait_until"]

DEMO = Path(__file__).resolve().parents[1] / "sites" / "demo_museum.yaml"

_TLS = ssl.create_default_context()
"""One TLS context for every health poll: httpx builds a new one (loading the CA bundle, about
20 ms of CPU) for each client it makes, and a server starting under load is polled hundreds of
times."""

GUI_TOKEN = "gui-token-12345678"
ADMIN_TOKEN = "admin-token-for-scale-tests"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def wait_until(
    check: Any, timeout: float = 30.0, what: str = "condition", interval: float = 0.1
) -> Any:
    """Poll an async ``check`` until it returns something truthy; fail after ``timeout``."""
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        result = await check()
        if result:
            return result
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await asyncio.sleep(interval)


class ServerProcess:
    """One `guidebot server --broker` child process."""

    def __init__(
        self,
        name: str,
        db_url: str,
        broker_url: str,
        log: Path,
        tokens: list[dict[str, str]] | None = None,
        *,
        site: Path = DEMO,
        env: dict[str, str] | None = None,
    ) -> None:
        self.db_url, self.broker_url, self.log_path = db_url, broker_url, log
        self.tokens = tokens or []
        self.site, self.env = site, dict(env or {})
        self.name, self.port = name, _free_port()
        env = {
            **os.environ,
            "GUIDEBOT_PROCESS_NAME": name,
            "GUIDEBOT_LEADER_POLL_S": "0.3",
            "GUIDEBOT_LEADER_LEASE_S": "1.5",
            "GUIDEBOT_ADMIN_TOKEN": ADMIN_TOKEN,
            "GUIDEBOT_BUILDING_ENABLED": "false",
            "GUIDEBOT_TOKENS": json.dumps(
                [{"token": GUI_TOKEN, "name": "gui", "role": "gui"}, *self.tokens]
            ),
        }
        guidebot = Path(sys.executable).parent / "guidebot"
        self.log = log.open("ab")
        self.process = subprocess.Popen(
            [str(guidebot), "server", "--port", str(self.port), "--db", db_url],
            env={**env, "GUIDEBOT_BROKER_URL": broker_url, "GUIDEBOT_SITE": str(site), **self.env},
            stdout=self.log,
            stderr=subprocess.STDOUT,
        )
        self.url = f"http://127.0.0.1:{self.port}"

    async def health(self) -> dict[str, Any] | None:
        try:
            async with httpx.AsyncClient(timeout=5, verify=_TLS) as http:
                response = await http.get(f"{self.url}/api/health")
        except httpx.HTTPError:
            return None
        return dict(response.json())

    async def ready(self) -> bool:
        health = await self.health()
        return bool(health and health["cluster"]["broker"]["connected"])

    async def until(self, check: Callable[[], Awaitable[Any]], what: str) -> Any:
        """Poll ``check`` until it returns something truthy, for as long as this process runs.

        A start or an election takes what it takes on a loaded machine (CI: a server still not
        answering after 60 s beside 50 other processes), so no wall-clock bound here: the
        caller's own time-out is the guard against a hang. A process that exits fails at once,
        with the end of its log."""
        while True:
            result = await check()
            if result:
                return result
            if self.process.poll() is not None:
                raise AssertionError(
                    f"server {self.name} exited ({self.process.returncode}) while waiting "
                    f"for {what}:\n{self.log_tail()}"
                )
            await asyncio.sleep(0.1)

    def log_tail(self, lines: int = 20) -> str:
        """The last lines of this process's log."""
        self.log.flush()
        text = self.log_path.read_text(errors="replace")
        return "\n".join(text.splitlines()[-lines:])

    async def leads(self) -> bool:
        """It leads and its components are up (``cluster.serving``)."""
        health = await self.health()
        return bool(health and health["cluster"]["serving"])

    def pause(self) -> None:
        """SIGSTOP: the process keeps its sockets but runs nothing (a frozen leader)."""
        self.process.send_signal(signal.SIGSTOP)

    def resume(self) -> None:
        self.process.send_signal(signal.SIGCONT)

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGKILL)
        self.process.wait(10)

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(15)
            except subprocess.TimeoutExpired:
                self.kill()
        self.log.close()


@contextlib.asynccontextmanager
async def start_servers(
    names: list[str],
    db_url: str,
    broker_url: str,
    logs: Path,
    tokens: list[dict[str, str]] | None = None,
    *,
    site: Path = DEMO,
    env: dict[str, str] | None = None,
) -> AsyncIterator[list[ServerProcess]]:
    """Start the servers one after the other (the first leads); ``tokens``: more static tokens
    ({"token", "name", "role"}) beside the GUI's; ``env``: settings over the defaults here
    (e.g. ``GUIDEBOT_BUILDING_ENABLED=true`` with a ``site`` on a running building_sim)."""
    servers: list[ServerProcess] = []
    try:
        for name in names:
            log = logs / f"{name}.log"
            servers.append(ServerProcess(name, db_url, broker_url, log, tokens, site=site, env=env))
            # The first one migrates the database; start the others once it leads (its broker
            # link up is not enough: under load a second process started then could take the
            # lease while the first was still starting, and tests expect the first to lead).
            await servers[-1].until(servers[-1].ready, f"server {name} to answer /api/health")
            if len(servers) == 1:
                await servers[0].until(servers[0].leads, f"server {name} to lead")
        yield servers
    finally:
        for server in servers:
            server.stop()
