"""A hub client over a real WebSocket for the scale-out tests; the server processes are
bench/servers.py's."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

import orjson
import websockets

from bench.servers import ServerProcess, wait_until

__all__ = ["WsClient"]


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
