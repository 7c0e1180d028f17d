"""Several real `guidebot server` processes on loopback, sharing a PostgreSQL database and a
redis-server, for the scale-out tests."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import httpx
import orjson
import websockets

from tests.server.helpers import DEMO

__all__ = ["ServerProcess", "WsClient", "start_servers", "wait_until"]

GUI_TOKEN = "gui-token-12345678"
ADMIN_TOKEN = "admin-token-for-scale-tests"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def wait_until(check: Any, timeout: float = 30.0, what: str = "condition") -> Any:
    """Poll an async ``check`` until it returns something truthy; fail after ``timeout``."""
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        result = await check()
        if result:
            return result
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        await asyncio.sleep(0.1)


class ServerProcess:
    """One `guidebot server --broker` child process."""

    def __init__(self, name: str, db_url: str, broker_url: str, log: Path) -> None:
        self.name, self.port = name, _free_port()
        env = {
            **os.environ,
            "GUIDEBOT_PROCESS_NAME": name,
            "GUIDEBOT_LEADER_POLL_S": "0.3",
            "GUIDEBOT_ADMIN_TOKEN": ADMIN_TOKEN,
            "GUIDEBOT_BUILDING_ENABLED": "false",
            "GUIDEBOT_TOKENS": json.dumps([{"token": GUI_TOKEN, "name": "gui", "role": "gui"}]),
        }
        guidebot = Path(sys.executable).parent / "guidebot"
        self.log = log.open("wb")
        self.process = subprocess.Popen(
            [str(guidebot), "server", "--port", str(self.port), "--db", db_url],
            env={**env, "GUIDEBOT_BROKER_URL": broker_url, "GUIDEBOT_SITE": str(DEMO)},
            stdout=self.log,
            stderr=subprocess.STDOUT,
        )
        self.url = f"http://127.0.0.1:{self.port}"

    async def health(self) -> dict[str, Any] | None:
        try:
            async with httpx.AsyncClient(timeout=5) as http:
                response = await http.get(f"{self.url}/api/health")
        except httpx.HTTPError:
            return None
        return dict(response.json())

    async def ready(self) -> bool:
        health = await self.health()
        return bool(health and health["cluster"]["broker"]["connected"])

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
    names: list[str], db_url: str, broker_url: str, logs: Path
) -> AsyncIterator[list[ServerProcess]]:
    servers: list[ServerProcess] = []
    try:
        for name in names:
            servers.append(ServerProcess(name, db_url, broker_url, logs / f"{name}.log"))
            # The first one migrates the database; start the others once it leads.
            await wait_until(servers[-1].ready, 60, f"server {name} to answer /api/health")
        yield servers
    finally:
        for server in servers:
            server.stop()


class WsClient:
    """A hub client over a real WebSocket that records every message it receives."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.received: list[dict[str, Any]] = []
        self._reader = asyncio.create_task(self._read())

    @classmethod
    async def connect(cls, server: ServerProcess, token: str, name: str = "") -> WsClient:
        url = f"ws://127.0.0.1:{server.port}/ws?token={token}" + (f"&name={name}" if name else "")
        client = cls(await websockets.connect(url))
        await wait_until(client._welcomed, 20, "welcome")
        return client

    async def _welcomed(self) -> bool:
        return any(m["type"] == "welcome" for m in self.received)

    async def _read(self) -> None:
        with contextlib.suppress(websockets.ConnectionClosed):
            async for frame in self.ws:
                data = orjson.loads(frame)
                self.received.extend(data if isinstance(data, list) else [data])

    async def send(self, type_: str, payload: dict[str, Any], **envelope: Any) -> None:
        await self.ws.send(orjson.dumps({"type": type_, "payload": payload, **envelope}))

    def of_type(self, type_: str) -> list[dict[str, Any]]:
        return [m for m in self.received if m["type"] == type_]

    async def close(self) -> None:
        await self.ws.close()
        self._reader.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._reader
