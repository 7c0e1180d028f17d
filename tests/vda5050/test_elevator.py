"""VDA 5050 vehicles in the demo museum: the real building simulator (Modbus doors and
elevator), the server's BuildingInterface, a real Mosquitto and the simulated vehicle; the
fleet's safety invariants are checked live on every hub message."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from guidebot.payloads.building import CallElevator
from guidebot.testing import wait_until
from guidebot.vda5050.schemas import problems
from guidebot.vda5050.topics import Vehicle
from robot_agent.testing import light_robot

from .broker import Mosquitto, mosquitto
from .museum import museum, vda_robot

pytestmark = pytest.mark.timeout(150)

V1 = Vehicle("Acme", "lift-rider")


@pytest.fixture
def broker() -> Iterator[Mosquitto]:
    with mosquitto() as b:
        yield b


@pytest.mark.parametrize("version", ["2.1.0", "3.0.0"])
async def test_a_vda_robot_rides_the_elevator_and_goes_through_the_door_upstairs(
    tmp_path: Path, broker: Mosquitto, version: str
) -> None:
    """3.0.0: the same ride with the museum's zone sets on both floors (the elevator area a
    RELEASE zone on each, its stops LINE_GUIDED, the doors LINE_GUIDED, the steps a
    SPEED_LIMIT): the vehicle asks for each RELEASE zone before it drives in."""
    rider = Vehicle(V1.manufacturer, V1.serial_number, version=version)
    async with museum(tmp_path, broker.url, [vda_robot("V1", rider, "charge_a")]) as m:
        async with m.vehicle(rider, "charge_a") as sim:
            tm = m.server.app.state.task_manager
            await wait_until(lambda: tm.robots["V1"].online, 15)
            # the cabin waits upstairs: the vehicle must wait for it at the landing
            tap = m.server.app.state.hub.endpoint("test_caller")
            tap.publish(CallElevator(elevator="lift", floor="F1"))
            await m.wait(
                lambda: any(p.payload["floor"] == "F1" for p in m.of("elevator_in_position")), 20
            )
            robot = next(iter(m.server.app.state.vda5050.robots.values()))
            robot.recall_s = 0.5  # the building holds a door 2 s (wall) per call
            task = await m.task("go_to", {"node": "gc1"})
            result = await m.ended(task)
            tap.close()
    assert result["state"] == "done", result
    assert (sim.last_node, sim.map_id) == ("gc1", "first")
    reached = [msg.payload["node"] for msg in m.of("node_reached")]
    assert reached == ["entrance", "hall", "lift0", "lift1", "landing", "door_f1", "gc1"]
    assert m.checker.violations == [], m.checker.violations
    assert m.checker.counts["cabin"] >= 2 and m.checker.counts["door"] >= 1
    states = [msg.payload["navigation"] for msg in m.of("robot_state")]
    assert "waiting_elevator" in states and "riding" in states
    # two orders, one per floor; the second after initPosition on the first floor's map
    orders = sim.orders_received
    assert {o["nodes"][0]["nodePosition"]["mapId"] for o in orders} == {"ground", "first"}
    first_floor = [o for o in orders if o["nodes"][0]["nodePosition"]["mapId"] == "first"]
    assert first_floor[0]["nodes"][0]["nodeId"] == "lift1"
    inits = [
        a
        for msg in sim.instant_received
        for a in msg["actions"]
        if a["actionType"] == "initPosition"
    ]
    assert len(inits) == 1
    params = {p["key"]: p["value"] for p in inits[0]["actionParameters"]}
    assert (params["lastNodeId"], params["mapId"]) == ("lift1", "first")
    for o in orders:
        assert problems("order", o) == []
    for msg in sim.instant_received:
        assert problems("instantActions", msg) == []
    calls = [msg.payload for msg in m.of("call_elevator") if msg.source == "V1"]
    assert {c["floor"] for c in calls} == {"F0", "F1"}
    releases = [msg.payload["area"] for msg in m.of("release_area") if msg.source == "V1"]
    assert releases == ["elevator"]
    assert not sim.errors
    if version == "3.0.0":
        assert set(sim.enabled) == {"ground", "first"}
        asked = [r["grantType"] for msg in sim.responses_received for r in msg["responses"]]
        assert "GRANTED" in asked and "REJECTED" not in asked, asked
        assert not sim.zone_requests


async def test_a_vda_robot_and_a_guidebot_robot_share_corridor_doors_and_elevator(
    tmp_path: Path, broker: Mosquitto
) -> None:
    robots = [
        {"name": "R1", "token": "robot-R1-test-token", "start_node": "charge_a"},
        vda_robot("V1", V1, "charge_b"),
    ]
    async with museum(tmp_path, broker.url, robots) as m:
        hub_url = m.server.url
        agent = light_robot(
            hub_url, "R1", "robot-R1-test-token", site=m.site_file, start_node="charge_a"
        )
        async with agent, m.vehicle(V1, "charge_b"):
            tm = m.server.app.state.task_manager
            await wait_until(lambda: tm.robots["V1"].online and tm.robots["R1"].online, 20)
            robot = next(iter(m.server.app.state.vda5050.robots.values()))
            robot.recall_s = 0.5
            # one tour each, both through the gallery door, the corridor, the lift and the
            # door upstairs
            tours = [
                await m.task("tour", {"tour": "highlights"}, robot="R1"),
                await m.task("tour", {"tour": "highlights"}, robot="V1"),
            ]
            results = [await m.ended(t, 120) for t in tours]
    assert [r["state"] for r in results] == ["done", "done"], results
    assert [r["robot"] for r in results] == ["R1", "V1"]
    assert m.checker.violations == [], m.checker.violations
    counts = m.checker.counts
    assert counts["area"] > 0 and counts["door"] > 0 and counts["cabin"] > 0, counts
    for name in ("R1", "V1"):
        grants = {g.payload["area"] for g in m.of("area_granted") if g.payload["robot"] == name}
        assert grants == {"corridor", "elevator"}, (name, grants)
        reached = {n.payload["node"] for n in m.of("node_reached") if n.payload["robot"] == name}
        assert {"door_hall", "corridor_w", "lift0", "lift1", "door_f1", "gc2"} <= reached
