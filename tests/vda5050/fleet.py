"""A real server with the VDA 5050 master control, a private Mosquitto and simulated VDA 5050
vehicles on loopback, on a small one-floor site: a line a-b-c-d-e with the restricted area
``corridor`` on c and d, GuideBot robot R1 (never connected) and VDA 5050 robot V1 at a."""

from __future__ import annotations

import asyncio
import contextlib
import itertools
from collections.abc import AsyncIterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import yaml

from backend.settings import Settings
from backend.testing import RunningServer, running_server
from guidebot.messages import Message
from guidebot.vda5050.sim import SimVehicle
from guidebot.vda5050.topics import Vehicle, parse_broker

LINE = ["a", "b", "c", "d", "e"]
V1 = Vehicle(manufacturer="Acme", serial_number="sn-0001")
TIME_SCALE = 10.0


def site_dict(v1: dict[str, Any] | None = None, **more: Any) -> dict[str, Any]:
    """The line; ``v1``: more fields of V1's entry (``vda_version``); ``more``: other site
    sections (no charging station or wait point by default: an idle robot stays where its
    task left it)."""
    return more | {
        "name": "VDA 5050 test line",
        "floors": [{"id": "F0", "name": "Ground", "level": 0}],
        "nodes": [
            {"id": n, "floor": "F0", "x": 4.0 * i, "y": 0.0, "passing_place": n in ("a", "b")}
            for i, n in enumerate(LINE)
        ],
        "edges": [{"a": a, "b": b} for a, b in itertools.pairwise(LINE)],
        "areas": [{"id": "corridor", "nodes": ["c", "d"]}],
        "pois": [
            {"id": "pb", "name": "Bee", "node": "b", "text": "Here is the bee."},
            {"id": "pe", "name": "End", "node": "e", "text": "The end of the line."},
        ],
        "tours": [{"id": "line", "name": "The line", "points": ["pb", "pe"]}],
        "robots": [
            {"name": "R1", "token": "robot-R1-test-token", "start_node": "e"},
            {
                "name": "V1",
                "token": "robot-V1-test-token",
                "start_node": "a",
                "interface": "vda5050",
                "manufacturer": V1.manufacturer,
                "serial_number": V1.serial_number,
                "map_ids": {"F0": "ground"},
            }
            | (v1 or {}),
        ],
    }


@dataclass
class Fleet:
    server: RunningServer
    http: httpx.AsyncClient
    seen: dict[str, list[Message]] = field(default_factory=dict)
    changed: asyncio.Event = field(default_factory=asyncio.Event)

    def of(self, type_: str) -> list[Message]:
        return self.seen.get(type_, [])

    def record(self, message: Message) -> None:
        self.seen.setdefault(message.type, []).append(message)
        self.changed.set()

    @property
    def master(self) -> Any:
        return self.server.app.state.vda5050

    def robot(self, name: str) -> Any:
        return self.server.app.state.task_manager.robots[name]

    async def task(self, kind: str, params: dict[str, Any]) -> str:
        answer = await self.http.post("/api/tasks", json={"kind": kind, "params": params})
        assert answer.status_code == 201, answer.text
        return str(answer.json()["id"])

    async def task_state(self, task_id: str) -> dict[str, Any]:
        answer = await self.http.get(f"/api/tasks/{task_id}")
        assert answer.status_code == 200, answer.text
        return dict(answer.json())


def vehicle(broker_url: str, **options: Any) -> SimVehicle:
    """V1, simulated, at node a of the line."""
    return SimVehicle(
        parse_broker(broker_url),
        V1,
        x=0.0,
        y=0.0,
        map_id="ground",
        node="a",
        speed=1.0,
        time_scale=TIME_SCALE,
        state_period_s=0.2,
        **options,
    )


@contextlib.asynccontextmanager
async def fleet(
    tmp_path: Path, broker_url: str, v1: dict[str, Any] | None = None, **more: Any
) -> AsyncIterator[Fleet]:
    site = tmp_path / "site.yaml"
    site.write_text(yaml.safe_dump(site_dict(v1, **more), sort_keys=False), encoding="utf-8")
    settings = Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db",
        site=site,
        building_enabled=False,
        mqtt_url=broker_url,
    )
    async with running_server(settings) as server:
        headers = {"Authorization": f"Bearer {server.admin_token}"}
        async with httpx.AsyncClient(base_url=server.url, headers=headers) as http:
            f = Fleet(server, http)
            tap = server.app.state.hub.endpoint("test_tap")
            tap.subscribe("*", f.record, tap=True)
            try:
                yield f
            finally:
                tap.close()
