"""Test helpers: the demo site, and a scripted robot that records what the server tells it."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

from guidebot.bus import Bus, Endpoint
from guidebot.messages import Message
from guidebot.site import Site, load_site_file

DEMO = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"


def demo_site() -> Site:
    return load_site_file(DEMO)


class RobotStub:
    """A robot as the server sees it: a named endpoint that reports state and answers."""

    def __init__(self, bus: Bus | Any, name: str, node: str, battery: float = 1.0) -> None:
        self.endpoint: Endpoint = bus.endpoint(name)
        self.name = name
        self.node = node
        self.battery = battery
        self.task_id: str | None = None
        self.inbox: list[Message] = []
        self._changed = asyncio.Event()
        self.endpoint.subscribe("*", self._receive)

    def _receive(self, msg: Message) -> None:
        if msg.destination == self.name:
            self.inbox.append(msg)
            self._changed.set()

    def of_type(self, type_: str) -> list[Message]:
        return [m for m in self.inbox if m.type == type_]

    async def wait_for(self, type_: str, count: int = 1, timeout: float = 10.0) -> Message:
        async def until() -> Message:
            while len(self.of_type(type_)) < count:
                self._changed.clear()
                await self._changed.wait()
            return self.of_type(type_)[count - 1]

        return await asyncio.wait_for(until(), timeout)

    def state(self, mode: str = "idle", **extra: Any) -> None:
        payload = {
            "robot": self.name,
            "node": self.node,
            "battery": self.battery,
            "mode": mode,
            "task_id": self.task_id,
            **extra,
        }
        self.endpoint.publish("robot_state", payload)

    def start(self, task_id: str) -> None:
        self.task_id = task_id
        self.endpoint.publish("task_started", {"task_id": task_id, "robot": self.name})

    def end(
        self, task_id: str, outcome: str = "done", reason: str = "", trouble: bool | None = None
    ) -> None:
        """task_ended; ``trouble`` (its flag) only when given, as an older robot sends none."""
        self.task_id = None
        payload = {"task_id": task_id, "robot": self.name, "outcome": outcome, "reason": reason}
        if trouble is not None:
            payload["trouble"] = trouble
        self.endpoint.publish("task_ended", payload)
