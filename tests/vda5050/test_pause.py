"""Pausing from the console (docs/vda5050.md, "Pause"; docs/console.md, "Fleet"): one VDA 5050
vehicle paused mid-drive by staff and let go on (``startPause`` / ``stopPause``), and the
fleet's pause, which holds a VDA 5050 vehicle's next task as it holds a GuideBot robot's. A
real server, a real Mosquitto, the simulated vehicle."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from guidebot.testing import wait_on, wait_until
from guidebot.vda5050.schemas import problems

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
