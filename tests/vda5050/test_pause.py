"""Pausing from the console (docs/vda5050.md, "Pause"; docs/console.md, "Fleet"): one VDA 5050
vehicle paused mid-drive by staff and let go on (``startPause`` / ``stopPause``), and the
fleet's pause, which holds a VDA 5050 vehicle's next task as it holds a GuideBot robot's. A
real server, a real Mosquitto, the simulated vehicle."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from guidebot.messages import Message
from guidebot.testing import wait_on, wait_until
from guidebot.vda5050.schemas import problems
from guidebot.vda5050.sim import SimVehicle

from .broker import Mosquitto, mosquitto
from .fleet import Fleet, fleet, vehicle
from .test_master import until_done

pytestmark = pytest.mark.timeout(90)


@pytest.fixture
def broker() -> Iterator[Mosquitto]:
    with mosquitto() as b:
        yield b


def navigation(f: Fleet) -> str | None:
    states = [m.payload for m in f.of("robot_state") if m.payload["robot"] == "V1"]
    return states[-1]["navigation"] if states else None


async def logged(f: Fleet, kind: str) -> list[dict[str, Any]]:
    reply = await f.http.get("/api/events", params={"kind": kind, "latest": "true"})
    return [row["data"] for row in reply.json()["events"]]


async def test_staff_pause_a_vehicle_mid_drive_and_let_it_go_on(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        task = await f.task("go_to", {"node": "e"})
        await wait_until(lambda: sim.driving, 20)
        answer = await f.http.post("/api/robots/V1/pause", json={"paused": True})
        assert answer.status_code == 200, answer.text
        assert answer.json() == {"robot": "V1", "paused": True}
        await wait_on(
            f.changed, lambda: sim.paused and not sim.driving and navigation(f) == "paused", 20
        )
        assert (await f.task_state(task))["state"] == "running"  # its task and order kept
        assert sim.order.nodes and sim.last_node != "e"
        answer = await f.http.post("/api/robots/V1/pause", json={"paused": False})
        assert answer.status_code == 200, answer.text
        result = await until_done(f, task)
        assert result["state"] == "done", result
        assert sim.last_node == "e" and not sim.paused
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        assert [k for k in kinds if k.endswith("Pause")] == ["startPause", "stopPause"]
        for message in sim.instant_received:
            assert problems("instantActions", message) == [], message
        assert await logged(f, "robot_paused") == [{"robot": "V1", "by": "admin"}]
        assert await logged(f, "robot_resumed") == [{"robot": "V1", "by": "admin"}]


async def test_pausing_a_guidebot_robot_or_an_unknown_one_is_refused_clearly(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f:
        answer = await f.http.post("/api/robots/R1/pause", json={"paused": True})
        assert answer.status_code == 409, answer.text
        assert "R1 runs GuideBot's robot agent" in answer.json()["detail"]
        answer = await f.http.post("/api/robots/V1/pause", json={"paused": True})
        assert answer.status_code == 409 and "V1 is offline" in answer.json()["detail"]
        answer = await f.http.post("/api/robots/V9/pause", json={"paused": True})
        assert answer.status_code == 404, answer.text
        answer = await f.http.post("/api/robots/V1/pause", json={"paused": "maybe"})
        assert answer.status_code == 422, answer.text


async def test_a_paused_fleet_gives_a_vehicle_no_task_until_resumed(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        answer = await f.http.post("/api/fleet/pause", json={"reason": "drill"})
        assert answer.status_code == 200, answer.text
        task = await f.task("go_to", {"node": "b"})
        assert (await f.task_state(task))["state"] == "queued"  # V1 is free: the fleet waits
        assert sim.orders_received == []
        answer = await f.http.post("/api/fleet/resume")
        assert answer.status_code == 200, answer.text
        result = await until_done(f, task)
        assert result["state"] == "done" and sim.last_node == "b", result


DOOR_AT_B = {
    "modules": [
        {
            "id": "m1",
            "port": 1,
            "points": [{"name": "door_b_open", "address": 0, "kind": "coil", "node": "b"}],
        }
    ],
    "doors": [{"id": "door_b", "node": "b", "open": {"module": "m1", "point": "door_b_open"}}],
}
"""The line with a door on b (its module never polled: the test plays the building)."""


class DoorAtB:
    """Plays the building on the server's hub (its BuildingInterface is off), as the
    interface does: each open_door of door_b is answered (door_opened broadcast, then the
    answer to the requester) unless ``jammed``; ``close()`` closes it under its holders (the
    building's own timer, staff)."""

    def __init__(self, f: Fleet, *, jammed: bool = False) -> None:
        self.ep = f.server.app.state.hub.endpoint("building")
        self.jammed = jammed
        self.ep.subscribe("open_door", self._open)

    def _open(self, msg: Message) -> None:
        if not self.jammed:  # answered after the request's handler, as the interface's task
            asyncio.get_running_loop().call_soon(self._answer, msg)

    def _answer(self, msg: Message) -> None:
        self.ep.publish("door_opened", {"door": "door_b"})
        self.ep.publish(
            "door_opened", {"door": "door_b"}, destination=msg.source, correlation_id=msg.id
        )

    def close(self) -> None:
        self.ep.publish("door_closed", {"door": "door_b"})


def pauses(sim: SimVehicle) -> list[str]:
    kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
    return [k for k in kinds if k in ("startPause", "stopPause")]


@pytest.mark.parametrize("staff", [False, True], ids=["door", "door_and_staff"])
async def test_a_new_master_tells_its_own_door_pause_from_staffs(
    tmp_path: Path, broker: Mosquitto, staff: bool
) -> None:
    """The master paused V1 before door_b (closed under its hold before V1 passed it) when the
    server stopped (a fail-over's new leader is the same: a new master control on the same
    database). The next master found the vehicle paused and could not tell its own pause from
    staff's: V1 stayed paused until staff let it go on. The pause's owner is in the event log:
    the new master lets V1 go on once the door is answered, unless staff paused it too."""
    async with vehicle(broker.url) as sim:
        sim.speed = 0.1  # 4 s of wall time from a to b
        async with fleet(tmp_path, broker.url, **DOOR_AT_B) as f:
            building = DoorAtB(f)
            await wait_until(lambda: f.robot("V1").online, 15)
            task = await f.task("go_to", {"node": "e"})
            await wait_until(lambda: any(n["nodeId"] == "b" for n in sim.order.nodes), 15)
            await wait_until(lambda: sim.order.nodes[0]["released"] and sim.driving, 15)
            building.jammed = True
            building.close()
            await wait_until(lambda: sim.paused and not sim.driving, 10)
            assert sim.last_node == "a" and pauses(sim) == ["startPause"]
            if staff:
                answer = await f.http.post("/api/robots/V1/pause", json={"paused": True})
                assert answer.status_code == 200, answer.text
        async with fleet(tmp_path, broker.url, **DOOR_AT_B) as f:
            DoorAtB(f)  # the door works again: answered at once
            if staff:
                v1 = next(r for r in f.master.robots.values() if r.name == "V1")
                await wait_until(lambda: v1.task_id == task and v1.paused_for is None, 20)
                await wait_on(f.changed, lambda: navigation(f) == "paused", 10)
                assert sim.paused and pauses(sim) == ["startPause", "startPause"]
                answer = await f.http.post("/api/robots/V1/pause", json={"paused": False})
                assert answer.status_code == 200, answer.text
            result = await until_done(f, task, 60)
            assert result["state"] == "done", result
        assert sim.last_node == "e" and not sim.paused
        assert pauses(sim)[-1] == "stopPause" and pauses(sim).count("stopPause") == 1
        assert not sim.errors
