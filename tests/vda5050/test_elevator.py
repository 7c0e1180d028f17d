"""A VDA 5050 vehicle rides the demo museum's Modbus elevator: the real building simulator, the
server's BuildingInterface, a real Mosquitto and the simulated vehicle; the fleet's safety
invariants are checked live on every hub message."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from backend.settings import Settings
from backend.testing import running_server
from building_sim.simulator import BuildingSimulator
from guidebot.invariants import InvariantChecker
from guidebot.messages import Message
from guidebot.payloads.building import CallElevator
from guidebot.site.building_config import BuildingConfig
from guidebot.site.yamlio import load_site_file
from guidebot.testing import wait_on, wait_until
from guidebot.vda5050.schemas import problems
from guidebot.vda5050.sim import SimVehicle
from guidebot.vda5050.topics import Vehicle, parse_broker

from .broker import Mosquitto, mosquitto

pytestmark = pytest.mark.timeout(120)

SITE = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"
BUILDING_TIME_SCALE = 10.0
V1 = Vehicle("Acme", "lift-rider")


@pytest.fixture
def broker() -> Iterator[Mosquitto]:
    with mosquitto() as b:
        yield b


async def test_a_vda_robot_rides_the_elevator_and_goes_through_the_door_upstairs(
    tmp_path: Path, broker: Mosquitto
) -> None:
    site = load_site_file(SITE)
    config = BuildingConfig(
        modules=site.modules, doors=site.doors, elevators=site.elevators, buttons=site.buttons
    )
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
        data["robots"] = [
            {
                "name": "V1",
                "token": "robot-V1-test-token",
                "start_node": "charge_a",
                "interface": "vda5050",
                "manufacturer": V1.manufacturer,
                "serial_number": V1.serial_number,
                "map_ids": {"F0": "ground", "F1": "first"},
            }
        ]
        site_file = tmp_path / "site.yaml"
        site_file.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        settings = Settings(
            db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", site=site_file, mqtt_url=broker.url
        )
        checker = InvariantChecker.from_site(site)
        seen: list[Message] = []
        changed = asyncio.Event()
        loop = asyncio.get_running_loop()

        def record(message: Message) -> None:
            seen.append(message)
            changed.set()
            if message.type == "area_granted":  # published inside its cause's handler
                loop.call_soon(checker.feed_message, message)
            else:
                checker.feed_message(message)

        async with running_server(settings) as server:
            tap = server.app.state.hub.endpoint("test_tap")
            tap.subscribe("*", record, tap=True)
            start = site.nodes[[n.id for n in site.nodes].index("charge_a")]
            sim = SimVehicle(
                parse_broker(broker.url),
                V1,
                x=start.x,
                y=start.y,
                map_id="ground",
                node="charge_a",
                speed=1.0,
                time_scale=10.0,
                state_period_s=0.2,
            )
            async with sim:
                tm = server.app.state.task_manager
                await wait_until(lambda: tm.robots["V1"].online, 15)
                # the cabin waits upstairs: the vehicle must wait for it at the landing
                tap.publish(CallElevator(elevator="lift", floor="F1"))
                await wait_on(
                    changed,
                    lambda: any(
                        m.type == "elevator_in_position" and m.payload["floor"] == "F1"
                        for m in seen
                    ),
                    20,
                )
                robot = next(iter(server.app.state.vda5050.robots.values()))
                robot.recall_s = 0.5  # the building holds a door 2 s (wall) per call
                headers = {"Authorization": f"Bearer {server.admin_token}"}
                async with httpx.AsyncClient(base_url=server.url, headers=headers) as http:
                    answer = await http.post(
                        "/api/tasks", json={"kind": "go_to", "params": {"node": "gc1"}}
                    )
                    assert answer.status_code == 201, answer.text
                    task = answer.json()["id"]

                    def ended() -> bool:
                        return any(
                            m.type == "task_ended" and m.payload["task_id"] == task for m in seen
                        )

                    await wait_on(changed, ended, 90)
                    result = (await http.get(f"/api/tasks/{task}")).json()
            tap.close()
    assert result["state"] == "done", result
    assert (sim.last_node, sim.map_id) == ("gc1", "first")
    reached = [m.payload["node"] for m in seen if m.type == "node_reached"]
    assert reached == ["entrance", "hall", "lift0", "lift1", "landing", "door_f1", "gc1"]
    assert checker.violations == [], checker.violations
    states = [m.payload["navigation"] for m in seen if m.type == "robot_state"]
    assert "waiting_elevator" in states and "riding" in states
    assert checker.counts["cabin"] >= 2 and checker.counts["door"] >= 1
    # two orders, one per floor; the second after initPosition on the first floor's map
    orders = sim.orders_received
    assert {o["nodes"][0]["nodePosition"]["mapId"] for o in orders} == {"ground", "first"}
    first_floor = [o for o in orders if o["nodes"][0]["nodePosition"]["mapId"] == "first"]
    assert first_floor[0]["nodes"][0]["nodeId"] == "lift1"
    inits = [
        a for m in sim.instant_received for a in m["actions"] if a["actionType"] == "initPosition"
    ]
    assert len(inits) == 1
    params = {p["key"]: p["value"] for p in inits[0]["actionParameters"]}
    assert (params["lastNodeId"], params["mapId"]) == ("lift1", "first")
    for o in orders:
        assert problems("order", o) == []
    for m in sim.instant_received:
        assert problems("instantActions", m) == []
    calls = [m.payload for m in seen if m.type == "call_elevator" and m.source == "V1"]
    assert {c["floor"] for c in calls} == {"F0", "F1"}
    releases = [m.payload["area"] for m in seen if m.type == "release_area" and m.source == "V1"]
    assert releases == ["elevator"]
