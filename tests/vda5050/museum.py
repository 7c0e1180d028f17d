"""The demo museum with its building simulator (Modbus doors and elevator), a real server with
the VDA 5050 master control, a private Mosquitto and the live invariant checker fed with every
hub message: for tests where VDA 5050 vehicles meet doors, the elevator and GuideBot robots."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import yaml

from backend.settings import Settings
from backend.testing import RunningServer, running_server
from building_sim.simulator import BuildingSimulator
from guidebot.invariants import InvariantChecker
from guidebot.messages import Message
from guidebot.site.building_config import BuildingConfig
from guidebot.site.schema import Site
from guidebot.site.yamlio import load_site_file
from guidebot.testing import wait_on
from guidebot.vda5050.sim import SimVehicle
from guidebot.vda5050.topics import Vehicle, parse_broker

SITE = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"
BUILDING_TIME_SCALE = 10.0
MAPS = {"F0": "ground", "F1": "first"}


def vda_robot(name: str, vehicle: Vehicle, start_node: str) -> dict[str, Any]:
    return {
        "name": name,
        "token": f"robot-{name}-test-token",
        "start_node": start_node,
        "interface": "vda5050",
        "manufacturer": vehicle.manufacturer,
        "serial_number": vehicle.serial_number,
        "map_ids": MAPS,
        "vda_version": vehicle.version,
    }


@dataclass
class Museum:
    site: Site
    site_file: Path
    server: RunningServer
    http: httpx.AsyncClient
    checker: InvariantChecker
    broker_url: str
    seen: list[Message] = field(default_factory=list)
    changed: asyncio.Event = field(default_factory=asyncio.Event)

    def of(self, type_: str) -> list[Message]:
        return [m for m in self.seen if m.type == type_]

    async def wait(self, predicate: Callable[[], Any], timeout: float = 60.0) -> None:
        await wait_on(self.changed, predicate, timeout)

    def vehicle(self, vehicle: Vehicle, node: str) -> SimVehicle:
        """A simulated vehicle on ``node`` (its floor's map)."""
        start = next(n for n in self.site.nodes if n.id == node)
        return SimVehicle(
            parse_broker(self.broker_url),
            vehicle,
            x=start.x,
            y=start.y,
            map_id=MAPS[start.floor],
            node=node,
            speed=1.0,
            time_scale=10.0,
            state_period_s=0.2,
        )

    async def task(self, kind: str, params: dict[str, Any], robot: str | None = None) -> str:
        body = {"kind": kind, "params": params} | ({"robot": robot} if robot else {})
        answer = await self.http.post("/api/tasks", json=body)
        assert answer.status_code == 201, answer.text
        return str(answer.json()["id"])

    async def ended(self, task_id: str, timeout: float = 90.0) -> dict[str, Any]:
        await self.wait(
            lambda: any(m.payload["task_id"] == task_id for m in self.of("task_ended")), timeout
        )
        return dict((await self.http.get(f"/api/tasks/{task_id}")).json())


@contextlib.asynccontextmanager
async def museum(
    tmp_path: Path, broker_url: str, robots: list[dict[str, Any]]
) -> AsyncIterator[Museum]:
    site = load_site_file(SITE)
    config = BuildingConfig(
        modules=site.modules, doors=site.doors, elevators=site.elevators, buttons=site.buttons
    )
    # The lift's door stays open 2 s of wall time per call, as in tests/robot/test_e2e.py; a
    # door closes 2 s after it opened, held or not (a fault the fleet must survive: a vehicle
    # whose door closes in front of it is paused until it is open again, docs/vda5050.md).
    building_sim = BuildingSimulator(
        config,
        time_scale=BUILDING_TIME_SCALE,
        port_zero=True,
        door_hold_s=2.0 * BUILDING_TIME_SCALE,
        elevator_hold_s=2.0 * BUILDING_TIME_SCALE,
    )
    async with building_sim as building:
        data: dict[str, Any] = site.model_dump(mode="json")
        for module in data["modules"]:
            module["port"] = building.ports[module["id"]]
        data["robots"] = robots
        site_file = tmp_path / "site.yaml"
        site_file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        settings = Settings(
            db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", site=site_file, mqtt_url=broker_url
        )
        checker = InvariantChecker.from_site(site)
        loop = asyncio.get_running_loop()
        async with running_server(settings) as server:
            headers = {"Authorization": f"Bearer {server.admin_token}"}
            async with httpx.AsyncClient(base_url=server.url, headers=headers) as http:
                m = Museum(site, site_file, server, http, checker, broker_url)

                def record(message: Message) -> None:
                    m.seen.append(message)
                    m.changed.set()
                    if message.type == "area_granted":  # published inside its cause's handler
                        loop.call_soon(checker.feed_message, message)
                    else:
                        checker.feed_message(message)

                tap = server.app.state.hub.endpoint("test_tap")
                tap.subscribe("*", record, tap=True)
                try:
                    yield m
                finally:
                    tap.close()
