"""The master control end to end: a real server, a real Mosquitto, the simulated vehicle; every
order and instant action the vehicle received is checked against the official schema (the
simulated vehicle refuses what its schema refuses, with an error in its state)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from backend.tasks.model import FINAL_STATES
from guidebot.testing import wait_on, wait_until
from guidebot.vda5050.schemas import problems

from .broker import Mosquitto, mosquitto
from .fleet import Fleet, fleet, vehicle

pytestmark = pytest.mark.timeout(90)


@pytest.fixture
def broker() -> Iterator[Mosquitto]:
    with mosquitto() as b:
        yield b


def released(order: dict) -> list[str]:
    return [n["nodeId"] for n in order["nodes"] if n["released"]]


def all_valid(messages: list[dict], topic: str) -> None:
    for message in messages:
        assert problems(topic, message) == [], message


async def until_done(f: Fleet, task_id: str, timeout: float = 30.0) -> dict:
    state: dict = {}

    def ended() -> bool:
        return any(m.payload.get("task_id") == task_id for m in f.of("task_ended"))

    await wait_on(f.changed, ended, timeout)
    await wait_until(lambda: f.server.app.state.task_manager.tasks[task_id].state in FINAL_STATES)
    state = await f.task_state(task_id)
    return state


async def test_go_to_drives_the_vehicle_through_the_corridor_lock(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        task = await f.task("go_to", {"node": "e"})
        result = await until_done(f, task)
        assert result["state"] == "done", result
        assert sim.last_node == "e"
        # the first order stops before the corridor, granted after: the update extends it
        assert released(sim.orders_received[0]) == ["a", "b"]
        assert sim.orders_received[0]["nodes"][-1]["nodeId"] == "e"  # the rest is horizon
        update = sim.orders_received[-1]
        assert update["orderUpdateId"] >= 1 and update["nodes"][0]["nodeId"] == "b"
        assert released(update)[-1] == "e"
        all_valid(sim.orders_received, "order")
        assert not sim.errors
        reached = [m.payload["node"] for m in f.of("node_reached") if m.source == "V1"]
        assert reached == ["b", "c", "d", "e"]
        grants = [m for m in f.of("area_granted") if m.payload["robot"] == "V1"]
        assert [m.payload["area"] for m in grants] == ["corridor"]
        releases = [m for m in f.of("release_area") if m.source == "V1"]
        assert [m.payload["area"] for m in releases] == ["corridor"]
        traffic = f.server.app.state.traffic
        assert traffic.locks.holder("corridor") is None
        state = f.of("robot_state")[-1].payload
        assert state["robot"] == "V1" and state["node"] == "e" and state["mode"] == "idle"
