"""Navigation over the real Traffic Manager and the simulated base, on one in-process Bus."""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from typing import Any, Literal

import pytest

from backend.closure import Closure, closed_nodes
from backend.traffic.manager import TrafficManager
from guidebot.bus import Bus, Endpoint
from guidebot.messages import Message
from guidebot.site.schema import Site
from guidebot.testing import wait_until
from robot_agent.clock import Clock
from robot_agent.motion import NavigationError
from robot_agent.navigation import Navigator
from robot_agent.sim_base import SimulatedBase


@dataclass
class Rig:
    bus: Bus
    nav: Navigator
    base: SimulatedBase
    building: Any
    traffic: TrafficManager
    seen: Any


@pytest.fixture
async def rig(demo_site: Site, helpers: Any) -> AsyncIterator[Rig]:
    bus = Bus()
    clock = Clock(time_scale=20.0)
    traffic = TrafficManager(bus.endpoint("traffic"), demo_site)
    await traffic.start()
    building = helpers.BuildingStandIn(bus)
    seen = helpers.Recorder(
        bus.endpoint("test"),
        "set_velocity",
        "request_area",
        "area_granted",
        "release_area",
        "open_door",
        "call_elevator",
        "goal_reached",
        "navigation_failed",
        "robot_fault",
    )
    base = SimulatedBase(bus.endpoint("R1.base"), clock)
    nav = Navigator(bus.endpoint("R1"), clock, "R1", start_node="charge_a")
    await nav.start()
    await base.start()
    yield Rig(bus, nav, base, building, traffic, seen)
    await nav.stop()
    await base.stop()
    await traffic.stop()


async def test_navigate_through_door_corridor_area(rig: Rig) -> None:
    """charge_a -> gb1: through door_gallery and the restricted corridor."""
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached") or rig.seen.of("navigation_failed"))
    assert not rig.seen.of("navigation_failed"), rig.seen.of("navigation_failed")[0].payload
    assert rig.nav.node == "gb1"
    assert math.hypot(rig.nav.x - 30, rig.nav.y - 0) < 0.3
    assert [m.payload["door"] for m in rig.seen.of("open_door")] == ["door_gallery"]
    assert [m.payload["area"] for m in rig.seen.of("request_area")] == ["corridor"]
    assert [m.payload["area"] for m in rig.seen.of("area_granted")] == ["corridor"]
    assert [m.payload["area"] for m in rig.seen.of("release_area")] == ["corridor"]
    # The base really moved: many velocity commands, and the last one stops it.
    assert len(rig.seen.of("set_velocity")) > 10
    assert rig.seen.of("set_velocity")[-1].payload == {"v": 0.0, "w": 0.0}


async def test_navigate_with_elevator_ride(rig: Rig) -> None:
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gc1"})
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached") or rig.seen.of("navigation_failed"))
    assert not rig.seen.of("navigation_failed"), rig.seen.of("navigation_failed")[0].payload
    assert rig.nav.node == "gc1" and rig.nav.floor == "F1"
    # Called to F0, called again while driving in (8 m, about 11 s: the door must not close
    # on the robot; the building holds it 8 s per call), then sent to F1, and called there
    # again while it gets out (at once: the door has stood open since the cabin arrived).
    calls = rig.building.calls
    up = calls.index(("lift", "F1"))
    assert up >= 2 and set(calls[:up]) == {("lift", "F0")}, calls
    assert len(calls) - up >= 2 and set(calls[up:]) == {("lift", "F1")}, calls
    assert rig.building.opened == ["door_upstairs"]
    assert [m.payload["area"] for m in rig.seen.of("request_area")] == ["elevator"]
    assert [m.payload["area"] for m in rig.seen.of("release_area")] == ["elevator"]


async def test_a_robot_gets_out_of_a_cabin_only_while_it_stands_open(rig: Rig) -> None:
    """The cabin's door closes as the robot arrives upstairs (at time scale 10 it stands open
    0.8 s of wall time, and the soak's robots reported lift1 after it had closed): the robot
    does not drive out through the closed door. It calls the cabin to its floor and gets out
    once the building reports it open there again, calling to keep it open on the way out."""
    building = rig.bus.endpoint("building-broadcast")
    closed_at: list[int] = []

    def on_reached(message: Message) -> None:
        if message.payload["node"] == "lift1" and not closed_at:
            rig.building.delay_s = 3600.0  # the cabin opens again when this test says
            building.publish(
                "elevator_in_position", {"elevator": "lift", "floor": "F1", "door_open": False}
            )
            closed_at.append(len(rig.seen.messages))

    rig.bus.endpoint("watch").subscribe("node_reached", on_reached, tap=True)
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gc1"})
    await wait_until(  # the robot's state announces itself with no message
        lambda: (
            bool(closed_at or rig.seen.of("navigation_failed"))
            and (rig.nav.node != "lift1" or rig.nav.state == "waiting_elevator")
        ),
        20,
    )
    assert rig.nav.node == "lift1", f"drove out of a closed cabin to {rig.nav.node}"
    assert rig.building.calls[-1] == ("lift", "F1")  # called to its floor: the door opens
    after = rig.seen.messages[closed_at[0] :]
    moving = [m for m in after if m.type == "set_velocity" and m.payload.get("v")]
    assert moving == [], moving
    rig.building.delay_s = 0.05
    building.publish("elevator_in_position", {"elevator": "lift", "floor": "F1", "door_open": True})
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached") or rig.seen.of("navigation_failed"))
    assert rig.nav.node == "gc1" and not rig.seen.of("navigation_failed")
    out = [c for c in rig.building.calls if c == ("lift", "F1")]
    assert len(out) >= 3, rig.building.calls  # the ride, the call back, the keep-open call


async def test_bumper_hit_stops_and_reports(rig: Rig) -> None:
    rig.nav.bumper_pause_s = 2.0
    net = rig.bus.endpoint("net")
    net.publish("navigate_to", {"node": "hall"})
    await rig.seen.wait_for(lambda: len(rig.seen.of("set_velocity")) >= 3)
    rig.bus.endpoint("bumper").publish("bumper_hit", {"ring": 0, "index": 2})
    await rig.seen.wait_for(lambda: bool(rig.seen.of("robot_fault")))
    fault = rig.seen.of("robot_fault")[0].payload
    assert fault["kind"] == "bumper" and fault["robot"] == "R1"
    # It stops at once, then goes on and still reaches its goal.
    assert rig.seen.of("set_velocity")[-1].payload == {"v": 0.0, "w": 0.0}
    await rig.seen.wait_for(lambda: bool(rig.seen.of("goal_reached")))
    assert rig.nav.node == "hall"


async def test_base_fault_fails_the_goal(rig: Rig) -> None:
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})
    await rig.seen.wait_for(lambda: len(rig.seen.of("set_velocity")) >= 3)
    rig.bus.endpoint("base").publish("base_fault", {"reason": "motor module lost"})
    await rig.seen.wait_for(lambda: bool(rig.seen.of("navigation_failed")))
    assert "motor module lost" in rig.seen.of("navigation_failed")[0].payload["reason"]
    assert rig.seen.of("robot_fault")[0].payload["kind"] == "motor_lost"
    assert rig.seen.of("set_velocity")[-1].payload == {"v": 0.0, "w": 0.0}
    # While the fault lasts, new goals fail at once with a clear reason.
    rig.bus.endpoint("net2").publish("navigate_to", {"node": "hall"})
    await rig.seen.wait_for(lambda: len(rig.seen.of("navigation_failed")) >= 2)
    assert "base fault" in rig.seen.of("navigation_failed")[1].payload["reason"]


async def test_unknown_node_fails_with_the_traffic_managers_reason(rig: Rig) -> None:
    rig.bus.endpoint("net").publish("navigate_to", {"node": "nowhere"})
    await rig.seen.wait_for(lambda: bool(rig.seen.of("navigation_failed")))
    assert "nowhere" in rig.seen.of("navigation_failed")[0].payload["reason"]


async def test_navigate_to_without_a_node_fails_at_once(rig: Rig) -> None:
    request = rig.bus.endpoint("net").publish("navigate_to", {})
    [failed] = rig.seen.of("navigation_failed")
    assert failed.correlation_id == request.id
    assert failed.payload == {
        "node": None,
        "reason": "navigate_to needs a node id",
        "closed": False,
        "trouble": False,
    }


async def test_area_wait_and_yield_then_goal_reached(rig: Rig) -> None:
    """R2 holds the corridor: R1 waits at its edge, is told to yield (back off to hall), and
    reaches its goal once R2 has released the corridor."""
    r2 = rig.bus.endpoint("R2")
    r2.publish("request_area", {"robot": "R2", "area": "corridor"})
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})
    await rig.seen.wait_for(lambda: rig.seen.of("request_area")[1:])
    assert rig.nav.state == "waiting_area"
    rig.traffic.endpoint.publish(
        "area_yield", {"robot": "R1", "area": "corridor", "go_to_node": "hall"}, destination="R1"
    )
    await rig.seen.wait_for(lambda: rig.nav.yields == 1 and rig.nav.node == "hall")
    r2.publish("release_area", {"robot": "R2", "area": "corridor"})
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached"), timeout=30)
    assert rig.nav.node == "gb1"
    assert not rig.seen.of("navigation_failed")


async def test_a_robot_waiting_for_an_area_a_publish_removes_goes_on_at_once(rig: Rig) -> None:
    """R2 holds the corridor and R1 waits at its edge; a new site without the corridor tells R1
    at once (not at its navigation time-out), and R1 drives on without asking again."""
    r2 = rig.bus.endpoint("R2")
    r2.publish("request_area", {"robot": "R2", "area": "corridor"})
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})
    await rig.seen.wait_for(lambda: rig.seen.of("request_area")[1:])
    assert rig.nav.state == "waiting_area"
    site = rig.traffic.site
    rig.traffic.load_site(
        site.model_copy(update={"areas": [a for a in site.areas if a.id != "corridor"]})
    )
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached") or rig.seen.of("navigation_failed"))
    assert not rig.seen.of("navigation_failed"), rig.seen.of("navigation_failed")[0].payload
    assert rig.nav.node == "gb1"
    [told] = [m for m in rig.seen.of("area_granted") if m.destination == "R1"]
    assert told.payload["removed"] is True and told.payload["area"] == "corridor"
    asked = [m for m in rig.seen.of("request_area") if m.payload["robot"] == "R1"]
    assert len(asked) == 1  # not asked again at the corridor's second node
    assert not [m for m in rig.seen.of("release_area") if m.payload["robot"] == "R1"]
    assert rig.nav.areas_held() == []


async def test_a_waiting_robot_says_what_it_waits_for_and_asks_again_after_a_reconnect(
    rig: Rig, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level("INFO", logger="robot_agent.passage")
    r2 = rig.bus.endpoint("R2")
    r2.publish("request_area", {"robot": "R2", "area": "corridor"})
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})

    def asked() -> list[Any]:
        return [m for m in rig.seen.of("request_area") if m.payload["robot"] == "R1"]

    await rig.seen.wait_for(lambda: asked())
    assert rig.nav.state == "waiting_area" and rig.nav.areas_held() == []
    assert "R1: waiting for area corridor" in caplog.text
    building = rig.bus.endpoint("building-broadcast")
    building.publish("door_opened", {"door": "door_upstairs"})
    building.publish("elevator_in_position", {"elevator": "lift", "floor": "F0", "door_open": True})
    passage = rig.nav.passage
    assert "door_upstairs" in passage._doors_open and passage._elevators == {"lift": "F0"}
    rig.nav.link_lost()  # broadcasts are missed from now on: unknown is closed
    assert not passage._doors_open and not passage._elevators
    rig.nav.resync()  # the link is back, maybe to a restarted server: ask again
    assert len(asked()) == 2 and asked()[-1].payload == {"robot": "R1", "area": "corridor"}
    # 60 robot seconds (3 s of wall time here) later, a warning says it still waits.
    await rig.seen.wait_for(lambda: "still waiting for area corridor" in caplog.text, timeout=20)
    r2.publish("release_area", {"robot": "R2", "area": "corridor"})
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached"), timeout=30)
    assert "R1: area corridor came after" in caplog.text
    rig.nav.resync()  # nothing is waited for any more: nothing is asked
    assert len(asked()) == 2


async def test_a_robot_whose_link_is_down_does_not_enter_an_area_granted_meanwhile(
    rig: Rig,
) -> None:
    """The server may release an offline robot's grant it never saw used and give the area
    to another robot (docs/server.md, offline grace): so the robot does not enter while its
    link is down, and after the reconnect it asks again (found by the 30-minute soak)."""
    import asyncio

    r2 = rig.bus.endpoint("R2")
    r2.publish("request_area", {"robot": "R2", "area": "corridor"})
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})

    def asked() -> list[Any]:
        return [m for m in rig.seen.of("request_area") if m.payload["robot"] == "R1"]

    await rig.seen.wait_for(lambda: asked())
    rig.nav.link_lost()
    r2.publish("release_area", {"robot": "R2", "area": "corridor"})
    await rig.seen.wait_for(
        lambda: [m for m in rig.seen.of("area_granted") if m.destination == "R1"]
    )
    await asyncio.sleep(0.5)  # 10 robot seconds: it would be through the corridor by now
    assert rig.nav.state == "waiting_area" and rig.nav.node == "ga1"
    rig.nav.resync()
    assert len(asked()) == 2  # the grant it never used is asked for again
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached"), timeout=30)
    assert rig.nav.node == "gb1"


async def test_a_robot_waiting_at_the_lift_asks_again_for_the_lift_after_a_reconnect(
    rig: Rig, demo_site: Site
) -> None:
    """Granted the lift, waiting for its cabin, the robot loses its link; the server restarts
    without its grant and gives the lift to R2. Back online, the robot must not drive into
    the cabin on its old grant: it asks again and waits for R2 (the 30-minute soak saw two
    robots ride together when it did not)."""
    import asyncio

    rig.building.delay_s = 3600.0  # the cabin comes when this test says
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gc1"})
    await rig.seen.wait_for(lambda: rig.nav.state == "waiting_elevator")
    assert rig.nav.areas_held() == ["elevator"] and rig.nav.node == "hall"

    rig.nav.link_lost()
    await rig.traffic.stop()  # a new server life: no locks until the robots declare theirs
    traffic = TrafficManager(rig.bus.endpoint("traffic-2"), demo_site)
    await traffic.start()
    try:
        r2 = rig.bus.endpoint("R2")
        r2.publish("request_area", {"robot": "R2", "area": "elevator"})
        await rig.seen.wait_for(
            lambda: [m for m in rig.seen.of("area_granted") if m.destination == "R2"]
        )
        rig.nav.resync()
        assert rig.nav.areas_held() == []
        building = rig.bus.endpoint("building-broadcast")
        building.publish(
            "elevator_in_position", {"elevator": "lift", "floor": "F0", "door_open": True}
        )
        await rig.seen.wait_for(
            lambda: [m for m in rig.seen.of("request_area") if m.payload["robot"] == "R1"][1:]
        )
        await asyncio.sleep(0.5)  # 10 robot seconds: it would be in the cabin by now
        assert rig.nav.state == "waiting_area" and rig.nav.node == "hall"
        r2.publish("release_area", {"robot": "R2", "area": "elevator"})
        await rig.seen.wait_for(
            lambda: [m for m in rig.seen.of("area_granted") if m.destination == "R1"][1:]
        )
        await rig.seen.wait_for(lambda: rig.nav.node == "lift0", timeout=30)
    finally:
        await traffic.stop()


async def test_a_robot_waiting_its_turn_for_the_lift_calls_the_cabin_when_its_turn_comes(
    rig: Rig,
) -> None:
    """Issue 36 (the soak without faults): robots waiting for the lift's area called its
    cabin, which came and went for nobody, and the robot whose turn came had its call spent:
    it waited for its retry (70-90 s for a 20 s ride), and tours were still queued for the
    lift when the soak ended. Only the robot holding the lift calls it, as its turn comes."""
    r2 = rig.bus.endpoint("R2")
    r2.publish("request_area", {"robot": "R2", "area": "elevator"})
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gc1"})
    await rig.seen.wait_for(lambda: rig.nav.state == "waiting_area" and rig.nav.node == "hall")
    assert rig.building.calls == []
    r2.publish("release_area", {"robot": "R2", "area": "elevator"})
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached") or rig.seen.of("navigation_failed"))
    assert rig.nav.node == "gc1" and not rig.seen.of("navigation_failed")
    assert rig.building.calls[0] == ("lift", "F0")


async def test_a_goal_that_fails_at_an_areas_edge_gives_the_area_back(rig: Rig) -> None:
    """Granted the lift, waiting for its cabin, the robot's motor is lost and its goal fails.
    The next path must ask for the lift again: the server released it with the task (the
    30-minute soak saw the robot ride on the old grant with another robot)."""
    rig.building.delay_s = 3600.0
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gc1"})
    await rig.seen.wait_for(lambda: rig.nav.state == "waiting_elevator")
    assert rig.nav.areas_held() == ["elevator"]
    rig.bus.endpoint("base").publish("base_fault", {"reason": "motor module lost"})
    await rig.seen.wait_for(lambda: bool(rig.seen.of("navigation_failed")))
    assert rig.nav.areas_held() == [] and rig.nav.node == "hall"
    assert [m.payload["area"] for m in rig.seen.of("release_area")] == ["elevator"]
    assert rig.traffic.locks.holder("elevator") is None


async def test_a_goal_that_fails_mid_edge_keeps_the_area_the_robot_drove_into(rig: Rig) -> None:
    """Granted the corridor, the robot leaves ga1 for corridor_w and its motor is lost on
    the way: it may be inside the corridor (the Traffic Manager counts so too), so it keeps
    it. Released as "not entered", another robot was granted the corridor the stopped robot
    stood in."""
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})
    await rig.seen.wait_for(
        lambda: rig.nav.node == "ga1" and rig.nav.x > 16.0 and rig.nav.areas_held() == ["corridor"]
    )
    rig.bus.endpoint("base").publish("base_fault", {"reason": "motor module lost"})
    await rig.seen.wait_for(lambda: bool(rig.seen.of("navigation_failed")))
    assert rig.nav.node == "ga1" and rig.nav.x < 20.0  # on the edge, short of corridor_w
    assert rig.nav.areas_held() == ["corridor"]
    assert not [m for m in rig.seen.of("release_area") if m.payload["area"] == "corridor"]
    assert rig.traffic.locks.holder("corridor") == "R1"


async def test_a_grant_that_comes_between_paths_is_given_back_and_asked_for_again(
    rig: Rig,
) -> None:
    """A path gave up waiting for the corridor (closed ahead, a cancel): its request was
    granted after the path ended. The server may release such a grant at the robot's next
    robot_state between tasks and grant it to another, so the next path gives it back and
    asks again at the corridor's edge; driving in on it, two robots rode the lift together in
    the fault soak."""
    rig.nav.ep.publish("request_area", {"robot": "R1", "area": "corridor"})
    await rig.seen.wait_for(lambda: rig.nav.areas_held() == ["corridor"])  # granted, idle
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})
    await rig.seen.wait_for(lambda: bool(rig.seen.of("goal_reached")), timeout=30)
    corridor = [m.type for m in rig.seen.messages if m.payload.get("area") == "corridor"]
    assert corridor.count("request_area") == 2  # the stale grant given back, asked again
    assert "request_area" in corridor[corridor.index("release_area") :]


async def test_a_robot_on_the_live_site_plans_on_board_and_declares_its_path(
    rig: Rig, demo_site: Site
) -> None:
    """No get_path round trip before moving; the Traffic Manager still knows the path (its
    head-on rule needs it), the same one it would have given."""
    from robot_agent.agent import onboard_site

    rig.nav.planner = onboard_site(demo_site).planner
    rig.nav.plan_on_board = True
    replies: list[Any] = []
    rig.bus.endpoint("paths").subscribe("path", replies.append, tap=True)
    net = rig.bus.endpoint("net")
    net.publish("navigate_to", {"node": "gb1"})
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached") or rig.seen.of("navigation_failed"))
    assert not rig.seen.of("navigation_failed")
    assert replies[0].payload["nodes"][-1] == "gb1"
    assert rig.traffic._paths["R1"].nodes == replies[0].payload["nodes"]
    # A silent Traffic Manager is not waited for (without the on-board plan: path_timeout_s).
    await rig.traffic.stop()
    rig.nav.path_timeout_s = 600.0
    reached = len(rig.seen.of("goal_reached"))
    net.publish("navigate_to", {"node": "gb2"})
    await rig.seen.wait_for(
        lambda: len(rig.seen.of("goal_reached")) > reached or rig.seen.of("navigation_failed")
    )
    assert not rig.seen.of("navigation_failed") and rig.nav.node == "gb2"


async def test_an_on_board_plan_that_fails_asks_the_traffic_manager_for_the_reason(
    rig: Rig, demo_site: Site
) -> None:
    from robot_agent.agent import onboard_site

    rig.nav.planner = onboard_site(demo_site).planner
    rig.nav.plan_on_board = True
    rig.bus.endpoint("net").publish("navigate_to", {"node": "nowhere"})
    await rig.seen.wait_for(lambda: rig.seen.of("navigation_failed"))
    assert "nowhere" in str(rig.seen.of("navigation_failed")[0].payload)


async def test_a_stall_of_the_agents_own_process_does_not_make_the_robot_stuck() -> None:
    """At time scale 50 a 10 m drive's budget (77 robot seconds) is 1.5 s of wall time: an
    event loop blocked for 2.5 s (a starved process) used to end the goal as "stuck"; and, the
    stall beginning while the drive waited for odometry, as "no odometry from the base" (the
    base's next report came after the 2 s watchdog had fired). The stall begins there on
    purpose: the loop turn after a velocity command."""
    bus = Bus()
    clock = Clock(time_scale=50.0)
    base = SimulatedBase(bus.endpoint("R1.base"), clock)
    nav = Navigator(bus.endpoint("R1"), clock, "R1", start_node="charge_a")
    loop = asyncio.get_running_loop()
    stalls: list[asyncio.Handle] = []

    def stall_once(message: Message) -> None:
        if message.payload["v"] > 0 and not stalls:
            stalls.append(loop.call_soon(time.sleep, 2.5))  # the whole process stands still

    await nav.start()
    await base.start()
    try:
        await nav.turn_to(0.0)
        x, y = nav.x + 10.0, nav.y
        bus.endpoint("watch").subscribe("set_velocity", stall_once, tap=True)
        assert await asyncio.wait_for(nav.drive_to(x, y), 10.0) is True
        assert stalls
        assert math.hypot(nav.x - x, nav.y - y) < 0.3
    finally:
        await nav.stop()
        await base.stop()


async def test_a_slow_process_does_not_make_the_robot_stuck() -> None:
    """Every turn of the loop 0.3 s late (a loaded machine, each gap shorter than a stall of
    old, 0.5 s): the simulated base moves 0.1 s of each gap, so the goal's budget must count
    no more of it."""
    bus = Bus()
    clock = Clock(time_scale=50.0)
    base = SimulatedBase(bus.endpoint("R1.base"), clock)
    nav = Navigator(bus.endpoint("R1"), clock, "R1", start_node="charge_a")

    async def slow_process() -> None:
        while True:
            time.sleep(0.3)  # noqa: ASYNC251 -- the point: the process gets little CPU
            await asyncio.sleep(0)

    await nav.start()
    await base.start()
    try:
        await nav.turn_to(0.0)
        x, y = nav.x + 10.0, nav.y
        slow = asyncio.create_task(slow_process())
        try:
            assert await asyncio.wait_for(nav.drive_to(x, y), 60.0) is True
        finally:
            slow.cancel()
        assert math.hypot(nav.x - x, nav.y - y) < 0.3
    finally:
        await nav.stop()
        await base.stop()


async def test_a_silent_base_ends_the_goal_with_no_odometry() -> None:
    """The watchdog still fires when the base says nothing (and this process is not stalled)."""
    bus = Bus()
    nav = Navigator(bus.endpoint("R1"), Clock(time_scale=50.0), "R1", start_node="charge_a")
    await nav.start()
    try:
        with pytest.raises(NavigationError, match="no odometry from the base"):
            await asyncio.wait_for(nav.turn_to(0.0), 10.0)
    finally:
        await nav.stop()


async def test_a_robot_waiting_its_turn_for_an_area_does_not_give_up_while_linked(
    rig: Rig,
) -> None:
    """Issue 36: tours failed "timed out waiting for area elevator" behind a long lift queue.
    The wait is patient while the link is up (only time without it counts) and the robot asks
    again now and then, keeping its place in line."""
    rig.nav.passage.wait_timeout_s = 30.0  # robot seconds: 1.5 s of wall time here
    r2 = rig.bus.endpoint("R2")
    r2.publish("request_area", {"robot": "R2", "area": "corridor"})
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})

    def asked() -> list[Any]:
        return [m for m in rig.seen.of("request_area") if m.payload["robot"] == "R1"]

    await rig.seen.wait_for(lambda: asked())
    # Asked again after 140 robot seconds, long past the time-out: still waiting, not failed.
    await rig.seen.wait_for(lambda: len(asked()) >= 2, timeout=30)
    assert not rig.seen.of("navigation_failed") and rig.nav.state == "waiting_area"
    r2.publish("release_area", {"robot": "R2", "area": "corridor"})
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached"), timeout=30)


def close_door_gallery(
    rig: Rig, demo_site: Site, source: Literal["staff", "trouble"], reason: str
) -> Endpoint:
    """Close door_gallery (node door_hall) as staff or as trouble, and say so to the fleet
    (over the endpoint returned: the closures' own)."""
    shut = Closure(id="c1", kind="door", target="door_gallery", reason=reason, source=source)
    closed = closed_nodes(demo_site, [shut], time.time())
    rig.traffic.closures = lambda: closed
    closures = rig.bus.endpoint("closures")
    closures.publish("closures_changed", {"nodes": sorted(closed)})
    return closures


async def test_a_staff_closure_in_words_of_trouble_is_not_waited_for(
    rig: Rig, demo_site: Site, helpers: Any
) -> None:
    """The robot told trouble from the path refusal's reason text: staff who close a door
    "out of order" made a tour wait its whole ``trouble_wait_s`` for a door nobody would
    reopen. The ``path`` answer's ``trouble`` flag says it, the words are the visitor's."""
    paths = helpers.Recorder(rig.bus.endpoint("watch"), "path")
    close_door_gallery(rig, demo_site, "staff", "out of order")
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1", "trouble_wait_s": 36000.0})
    await rig.seen.wait_for(lambda: rig.seen.of("navigation_failed"))
    failed = rig.seen.of("navigation_failed")[0].payload
    assert failed["closed"] is True
    assert failed["reason"] == "door door_gallery closed: out of order"
    assert failed["trouble"] is False
    assert paths.of("path", closed=True, trouble=False)


async def test_a_goal_trouble_alone_cuts_off_fails_saying_so_typed(
    rig: Rig, demo_site: Site
) -> None:
    """The server told trouble from navigation_failed's reason text ("out of order"), which
    carries the closures' words: the failure says it with the ``path`` answer's typed flag."""
    close_door_gallery(rig, demo_site, "trouble", "door door_gallery not open in 4 s")
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1"})  # no trouble_wait_s
    await rig.seen.wait_for(lambda: rig.seen.of("navigation_failed"))
    failed = rig.seen.of("navigation_failed")[0].payload
    assert failed["closed"] is True and failed["trouble"] is True


async def test_a_way_only_trouble_cuts_off_is_waited_for(
    rig: Rig, demo_site: Site, helpers: Any
) -> None:
    paths = helpers.Recorder(rig.bus.endpoint("watch"), "path")
    closures = close_door_gallery(rig, demo_site, "trouble", "door door_gallery not open in 4 s")
    rig.bus.endpoint("net").publish("navigate_to", {"node": "gb1", "trouble_wait_s": 36000.0})
    await paths.wait_for(lambda: paths.of("path", closed=True, trouble=True))
    assert paths.of("path")[0].payload["reason"] == "door door_gallery out of order"
    # The door works again: the trouble lifts, and the robot plans again and goes.
    rig.traffic.closures = dict
    closures.publish("closures_changed", {"nodes": []})
    await rig.seen.wait_for(lambda: rig.seen.of("goal_reached") or rig.seen.of("navigation_failed"))
    assert not rig.seen.of("navigation_failed"), rig.seen.of("navigation_failed")[0].payload
    assert rig.nav.node == "gb1"
