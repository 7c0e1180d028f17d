"""Hub clients over a real WebSocket for `guidebot bench failover` and the scale-out tests
(tests/scale): a recording client, and a robot that asks for one restricted area."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from typing import Any

import orjson
import websockets

from .servers import ServerProcess, wait_until

__all__ = ["AREA", "ROBOT_TOKENS", "AreaRobot", "WsClient"]

AREA = "corridor"
"""The demo site's restricted corridor (nodes corridor_w, corridor_e)."""
ROBOT_TOKENS = {"R1": "robot-R1-demo-token", "R2": "robot-R2-demo-token"}
_sync = itertools.count()


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


class AreaRobot:
    """A site robot (R1, R2) that asks for, holds and leaves the corridor: enough robot to
    check the Traffic Manager's grants across processes without a whole robot agent."""

    def __init__(self, name: str, client: WsClient) -> None:
        self.name, self.client = name, client

    @classmethod
    async def connect(cls, server: ServerProcess, name: str) -> AreaRobot:
        return cls(name, await WsClient.connect(server, ROBOT_TOKENS[name]))

    async def synced(self) -> None:
        """Once the server answers a ping, it has read everything this robot sent before it."""
        ping_id = f"sync-{next(_sync)}"
        await self.client.send("ping", {}, id=ping_id)

        async def ponged() -> bool:
            return any(m.get("correlation_id") == ping_id for m in self.client.of_type("pong"))

        await wait_until(ponged, 20, f"{self.name}'s pong")

    def grants(self) -> int:
        return sum(1 for m in self.client.of_type("area_granted") if m["payload"]["area"] == AREA)

    async def granted(self, count: int, what: str, timeout: float = 20.0) -> None:
        async def enough() -> bool:
            return self.grants() >= count

        await wait_until(enough, timeout, what)

    async def ask(self) -> None:
        await self.client.send("request_area", {"robot": self.name, "area": AREA})
        await self.synced()

    async def release(self) -> None:
        await self.client.send("release_area", {"robot": self.name, "area": AREA})
        await self.synced()

    async def report(self, node: str, holding: bool) -> None:
        """robot_state: where it stands and what it holds (the resync a new leader takes)."""
        areas = [AREA] if holding else []
        await self.client.send("robot_state", {"robot": self.name, "node": node, "areas": areas})
        await self.synced()

    async def close(self) -> None:
        await self.client.close()
