"""A robot riding the lift when the fire alarm sounds gets out at the landing the cabin goes
to, not where it got in (issue 35: "A robot in an elevator leaves it at the landing the cabin
goes to"). Real pieces: the building simulator's Modbus/TCP modules, the server, and a robot
agent on virtual CAN (docs/emergency.md)."""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest

from building_sim.control import serve_control
from building_sim.devices import CabinState
from guidebot.invariants import InvariantChecker
from guidebot.messages import Message
from guidebot.site.schema import Site
from guidebot.site.yamlio import load_site_file
from robot_agent.navigation import NavState
from tests.robot.test_e2e import fleet_up

from .test_server import DEMO_SITE

pytestmark = pytest.mark.timeout(150)

ALARM = "/points/otb_ground/fire_alarm"
TRAVEL_S = 80.0
"""The lift's travel time (building seconds; 8 s of wall time at the tests' time scale): the
alarm reaches the robot while the cabin is between the floors."""


def _slow_lift() -> Site:
    site = load_site_file(DEMO_SITE)
    lifts = [e.model_copy(update={"travel_time_s": TRAVEL_S}) for e in site.elevators]
    return site.model_copy(update={"elevators": lifts})


async def test_a_robot_riding_the_lift_gets_out_at_the_landing_the_cabin_goes_to(
    tmp_path: Path,
) -> None:
    site = _slow_lift()
    async with fleet_up(tmp_path, site) as fleet, serve_control(fleet.building) as url:
        checker = InvariantChecker.from_site(site)
        hub = fleet.server.app.state.hub
        hub.endpoint("test-invariants").subscribe("*", checker.feed_message, tap=True)
        nav = fleet.agent.navigator
        cabin = fleet.building.elevators["lift"]
        task_id = await fleet.request_task("tour", {"tour": "upstairs"})
        # In the cabin, which has left the ground floor for the first floor.
        await fleet.wait_for(
            lambda: nav.state is NavState.RIDING and cabin.state is CabinState.moving, 90
        )
        assert nav.node == "lift0" and cabin.index == 0

        def reported(state: str) -> list[Message]:
            return [m for m in fleet.of("evacuation_state") if m.payload["state"] == state]

        def reached_since(start: int) -> list[str]:
            return [m.payload["node"] for m in fleet.of("node_reached")[start:]]

        reached = len(fleet.of("node_reached"))
        async with httpx.AsyncClient(base_url=url) as control:
            assert (await control.post(ALARM, json={"value": 1})).status_code == 200
        await fleet.wait_for(lambda: reported("stopped"))
        assert cabin.state is CabinState.moving, "the alarm came after the ride"
        [order] = fleet.of("evacuate")
        # The server saw it last in the cabin at F0: it sends the way from each landing.
        assert order.payload["path"][0] == "lift0"
        assert order.payload["landings"]["lift"]["F1"]["path"] == ["lift1", "landing"]
        assert order.payload["landings"]["lift"]["F0"]["path"] == order.payload["path"]
        assert "in elevator lift's cabin" in reported("stopped")[0].payload["why"]

        # It stays in the cabin (it does not drive out on the ground floor) until the cabin
        # stands at the first floor with its door open, gets out there and waits at the
        # landing, the first floor's safe spot.
        await fleet.wait_for(lambda: reported("safe") or len(reported("stuck")) >= 3, 90)
        assert reported("safe"), [m.payload for m in reported("stuck")]
        assert reported("safe")[-1].payload["node"] == "landing"
        assert reached_since(reached) == ["lift1", "landing"]
        assert nav.floor == "F1" and cabin.index == 1
        assert (await fleet.task(task_id))["state"] == "queued"
        # The server's record follows the landing it got out at.
        emergency = fleet.server.app.state.emergency
        entry = emergency.evacuation["R1"]
        assert (entry["safe_spot"], entry["path"]) == ("landing", ["lift1", "landing"])
        # No ride started and no escape route was entered during the alarm.
        assert checker.counts["elevator_ride"] >= 1
        assert checker.violations == []
