"""Doors over real Modbus/TCP: every pass opens the door, the door is held while a robot passes,
and a door that does not open stops the robot in front of it with an alert.

Real server (Task and Traffic Managers, BuildingInterface polling the building simulator),
robot agents on real WebSocket links; every hub message is checked by guidebot.invariants.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import httpx
import pytest

from tests.robot.safety_rig import fleet

pytestmark = pytest.mark.timeout(90)


async def test_one_robot_through_one_door_many_times_opens_it_each_pass(tmp_path: Path) -> None:
    async with fleet(tmp_path, ["R1"]) as f:
        door = f.building.doors["D0"]
        passes = 4
        for n in range(passes):
            await f.go("R1", "west" if n % 2 == 0 else "hall")
            # Once past it, the robot lets go and the door closes.
            await f.wait_for(lambda: door.state == "closed")
        assert len(f.of("open_door", door="D0")) == passes
        assert len(f.of("release_door", door="D0")) == passes
        assert door.openings == passes
        assert f.checker.counts["door"] == passes
        assert not f.checker.violations, f.checker.violations


async def test_two_robots_through_one_door_in_opposite_directions(tmp_path: Path) -> None:
    async with fleet(tmp_path, ["R1", "R2"], start={"R2": "w_dock"}) as f:
        await asyncio.gather(f.go("R1", "w_dock"), f.go("R2", "home2"))
        await f.wait_for(lambda: f.building.doors["D0"].state == "closed")
        for robot in ("R1", "R2"):
            assert [m.source for m in f.of("open_door", door="D0")].count(robot) == 1
            assert [m.source for m in f.of("release_door", door="D0")].count(robot) == 1
        assert f.checker.counts["door"] == 2
        assert not f.checker.violations, f.checker.violations


async def test_a_door_that_fails_to_open_stops_the_robot_and_it_goes_round_another_way(
    tmp_path: Path,
) -> None:
    """Issue 36, "Routing around trouble": D0 jams; the robot stops before it, the door is
    closed as trouble (staff are alerted of the failed command), and the robot plans again: up
    lift_a, through D1, down lift_b and back along the corridors to west, instead of waiting
    in front of the door for a repair (the old behaviour, up to 600 s)."""
    async with fleet(tmp_path, ["R1"]) as f:
        f.building.jam_door("D0")
        agent = f.agents["R1"]
        assert agent.navigator is not None
        nav = agent.navigator
        going = asyncio.create_task(f.go("R1", "west", timeout=80))
        await f.wait_for(lambda: f.of("closures_changed"), timeout=30)
        assert f.of("command_failed", command="open_door", target="D0")
        assert f.of("closures_changed")[0].payload["nodes"] == ["door0"]
        await going
        assert nav.node == "west" and nav.replans >= 1
        reached = [m.payload["node"] for m in f.of("node_reached")]
        assert "door0" not in reached and {"up_w", "door1", "up_e"} <= set(reached)
        assert f.building.doors["D0"].state == "closed"
        async with httpx.AsyncClient(base_url=f.server.url) as http:
            r = await http.get(
                "/api/events?kind=trouble_raised",
                headers={"Authorization": f"Bearer {f.server.admin_token}"},
            )
        [raised] = r.json()["events"]
        assert raised["data"]["what"] == "door D0" and raised["data"]["by"] == "building"
        assert not f.checker.violations, f.checker.violations


async def test_robots_report_their_floor_from_the_start(tmp_path: Path) -> None:
    """At its charging station, before any move, GET /api/robots knows the robot's floor
    and its robot_state its position (the console draws it there)."""
    async with fleet(tmp_path, ["R1"], start={"R1": "home2"}) as f:
        await f.wait_for(lambda: "R1" in f.states)
        assert f.states["R1"]["node"] == "home2" and f.states["R1"]["floor"] == "F0"
        async with httpx.AsyncClient(base_url=f.server.url) as http:
            r = await http.get(
                "/api/robots", headers={"Authorization": f"Bearer {f.server.admin_token}"}
            )
        [robot] = r.json()
        assert robot["node"] == "home2" and robot["floor"] == "F0"
        # robot_state places it at home2, not at the odometry's origin (0, 0)
        assert (f.states["R1"]["x"], f.states["R1"]["y"]) == (0.0, 3.0)
        assert not f.of("node_reached")


async def test_a_robot_waiting_at_a_door_staff_close_asks_again_and_goes_through(
    tmp_path: Path,
) -> None:
    """Staff close D0 (``close_door``, as an operator's hub client sends it) while R1 waits in
    front of it for its open_door (the door jammed for the moment): the building withdrew R1's
    request without an answer, and R1 waited its whole time-out (600 robot seconds) before a
    closed door. It is answered ``door_closed``, asks again and goes through; no failure, no
    alert, no trouble closure."""
    async with fleet(tmp_path, ["R1"]) as f:
        building = f.server.app.state.building
        building.command_margin_s = 300.0  # the jammed door's open_door never times out here
        f.building.jam_door("D0")
        going = asyncio.create_task(f.go("R1", "west", timeout=60))
        await f.wait_for(lambda: f.states.get("R1", {}).get("navigation") == "waiting_door")
        await f.wait_for(lambda: building.doors["D0"].holders)
        f.building.jam_door("D0", False)  # the coil is set: nothing moves until it is set again
        staff = f.server.app.state.hub.endpoint("staff")
        closed = await staff.request("close_door", {"door": "D0"}, timeout=30)
        assert closed.type == "door_closed", closed.payload
        await going
        async with httpx.AsyncClient(base_url=f.server.url) as http:
            alerts = await http.get(
                "/api/alerts", headers={"Authorization": f"Bearer {f.server.admin_token}"}
            )
        assert len(f.of("open_door", door="D0")) >= 2
        assert not f.of("command_failed")
        assert "door0" in [m.payload["node"] for m in f.of("node_reached")]
        assert [a["kind"] for a in alerts.json()] == []
        assert not f.checker.violations, f.checker.violations
