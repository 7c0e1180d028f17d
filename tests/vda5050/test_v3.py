"""The simulated vehicle speaking VDA 5050 3.0.0 through a real Mosquitto (docs/vda5050.md,
"The simulated vehicle", "Hibernation"): a tour end to end with its zone set and zone
requests answered through the lock table, and hibernation (shown, not dispatched, no alert).
The simulated vehicle checks every message it receives against the official 3.0.0 schema
(one refused is an error in its state: none here); the master control checks every one it
receives and sends."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from guidebot.processes import spawn_guidebot
from guidebot.testing import wait_on, wait_until
from guidebot.vda5050.schemas import problems
from guidebot.vda5050.sim import SimVehicle
from guidebot.vda5050.topics import Vehicle, parse_broker

from .broker import Mosquitto, mosquitto
from .fleet import TIME_SCALE, V1, Fleet, fleet

pytestmark = pytest.mark.timeout(90)

V3 = Vehicle(V1.manufacturer, V1.serial_number, version="3.0.0")


@pytest.fixture
def broker() -> Iterator[Mosquitto]:
    with mosquitto() as b:
        yield b


def vehicle_v3(broker_url: str) -> SimVehicle:
    """V1, simulated, speaking 3.0.0, at node a of the line."""
    return SimVehicle(
        parse_broker(broker_url),
        V3,
        map_id="ground",
        node="a",
        time_scale=TIME_SCALE,
        state_period_s=0.2,
    )


def v1_states(f: Fleet) -> list[dict[str, Any]]:
    return [m.payload for m in f.of("robot_state") if m.payload["robot"] == "V1"]


async def done(f: Fleet, task_id: str, timeout: float = 60.0) -> dict[str, Any]:
    await wait_on(
        f.changed,
        lambda: any(m.payload["task_id"] == task_id for m in f.of("task_ended")),
        timeout,
    )
    return await f.task_state(task_id)


async def test_a_tour_with_a_3_0_0_vehicle_end_to_end(tmp_path: Path, broker: Mosquitto) -> None:
    """The line tour: V1's zone set enabled, its request for the corridor GRANTED through
    the lock table before it drives in, given back once it is out; both stops spoken."""
    async with (
        fleet(tmp_path, broker.url, v1={"vda_version": "3.0.0"}) as f,
        vehicle_v3(broker.url) as sim,
    ):
        await wait_until(lambda: f.robot("V1").online, 15)
        robot = next(iter(f.master.robots.values()))
        await wait_until(lambda: robot.factsheet is not None and sim.enabled, 15)
        assert problems("factsheet", robot.factsheet, "3.0.0") == []
        assert robot.supported_zones == {"RELEASE", "BLOCKED", "SPEED_LIMIT", "LINE_GUIDED"}
        task = await f.task("tour", {"tour": "line"})
        result = await done(f, task)
        assert result["state"] == "done", result
        assert sim.last_node == "e" and not sim.errors
        progress = [
            (m.payload["index"], m.payload["stage"])
            for m in f.of("tour_progress")
            if m.payload["task_id"] == task
        ]
        assert progress == [(1, "arrived"), (1, "explained"), (2, "arrived"), (2, "explained")]
        reached = [m.payload["node"] for m in f.of("node_reached") if m.source == "V1"]
        assert reached == ["b", "c", "d", "e"]
        (zone_set,) = sim.zone_sets.values()
        assert sim.enabled == {"ground": zone_set["zoneSetId"]}
        answers = [r["grantType"] for m in sim.responses_received for r in m["responses"]]
        assert answers and answers[-1] == "GRANTED", answers
        await wait_until(lambda: not sim.zone_requests, 10)  # out of the zone: dropped
        await wait_until(lambda: f.server.app.state.traffic.locks.holder("corridor") is None)
        assert {o["version"] for o in sim.orders_received} == {"3.0.0"}
        assert all(problems("order", o, "3.0.0") == [] for o in sim.orders_received)
        assert all(problems("instantActions", m, "3.0.0") == [] for m in sim.instant_received)
        assert problems("state", sim.state(), "3.0.0") == []
        assert f.master.refused == 0


async def test_a_hibernating_vehicle_is_shown_not_dispatched_and_not_alerted(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """Staff send V1 to sleep: HIBERNATING, no state; the robot is offline to the fleet with
    navigation "hibernating", a task waits in the queue, no robot_lost alert. Woken, it
    takes the task."""
    async with (
        fleet(tmp_path, broker.url, v1={"vda_version": "3.0.0"}) as f,
        vehicle_v3(broker.url) as sim,
    ):
        tm, alerts = f.server.app.state.task_manager, f.server.app.state.alerts
        await wait_until(lambda: f.robot("V1").online, 15)
        answer = await f.http.post("/api/robots/V1/hibernate", json={"hibernating": True})
        assert answer.status_code == 200, answer.text
        await wait_until(lambda: sim.hibernating and not f.robot("V1").online, 15)
        last = v1_states(f)[-1]
        assert (last["mode"], last["navigation"]) == ("offline", "hibernating")
        seen = len(v1_states(f))
        task = await f.task("go_to", {"node": "e"})
        assert tm.tasks[task].state.value == "queued"
        again = await f.http.post("/api/robots/V1/hibernate", json={"hibernating": True})
        assert again.status_code == 409, again.text
        assert not alerts.is_active("robot_lost", "V1")
        assert len(v1_states(f)) == seen  # silent while asleep

        answer = await f.http.post("/api/robots/V1/hibernate", json={"hibernating": False})
        assert answer.status_code == 200, answer.text
        result = await done(f, task)
        assert result["state"] == "done" and result["robot"] == "V1", result
        assert not alerts.is_active("robot_lost", "V1")
        assert not sim.errors
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        assert kinds.count("startHibernation") == 1 and kinds.count("stopHibernation") == 1


async def test_the_simulator_process_speaks_its_site_entrys_3_0_0(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """`guidebot vda5050-sim --site --robot V1` (the command the demo runs) speaks the version
    V1's site entry says: 3.0.0 topics, state and factsheet; a go-to through the corridor."""
    async with fleet(tmp_path, broker.url, v1={"vda_version": "3.0.0"}) as f:
        args = ["vda5050-sim", "--broker", broker.url, "--site", str(tmp_path / "site.yaml")]
        args += ["--robot", "V1", "--time-scale", str(TIME_SCALE), "--state-period", "0.2"]
        process = spawn_guidebot(args)
        try:
            await wait_until(lambda: f.robot("V1").online, 30)
            robot = next(iter(f.master.robots.values()))
            await wait_until(lambda: robot.factsheet is not None, 15)
            assert robot.factsheet["version"] == "3.0.0" and robot.state["version"] == "3.0.0"
            assert "mobileRobotPosition" in robot.state
            task = await f.task("go_to", {"node": "e"})
            result = await done(f, task)
            assert result["state"] == "done", result
            assert f.master.refused == 0
        finally:
            process.terminate()
            process.wait(10)
