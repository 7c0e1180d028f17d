"""Building modes and trouble (backend/closures) and the run-time wait-cycle guard of the
Traffic Manager, over a real bus."""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import pytest

from backend.closure import Closure, ClosureRequest, closed_nodes
from backend.closures.service import ClosureService
from backend.closures.trouble import FIRST_HOLD_PART, trouble_of
from backend.detours import RouteClosed, path_avoiding
from backend.testing import running_server
from guidebot.bus import Bus
from guidebot.site import Site, validate_site
from guidebot.site.graph import SiteGraph

from .conftest import OPERATOR_TOKEN, PANEL_TOKEN, server_settings
from .helpers import RobotStub, demo_site
from .test_traffic import line_site, start_traffic


def closure(kind: str, target: str = "", nodes: list[str] | None = None, **kw: object) -> Closure:
    return Closure(
        id=f"c-{kind}-{target}",
        kind=kind,
        target=target,
        nodes=nodes or [],
        reason="cleaning",
        **kw,
    )  # type: ignore[arg-type]


def ring_site() -> Site:
    """s - p - g the short way, s - q1 - q2 - g the long way round; gallery P is p."""
    nodes = [
        {"id": "s", "floor": "F0", "x": 0, "y": 0},
        {"id": "p", "floor": "F0", "x": 5, "y": 0},
        {"id": "g", "floor": "F0", "x": 10, "y": 0},
        {"id": "q1", "floor": "F0", "x": 0, "y": 10},
        {"id": "q2", "floor": "F0", "x": 10, "y": 10},
    ]
    pairs = [("s", "p"), ("p", "g"), ("s", "q1"), ("q1", "q2"), ("q2", "g")]
    return validate_site(
        {
            "name": "ring",
            "floors": [{"id": "F0"}],
            "nodes": nodes,
            "edges": [{"a": a, "b": b} for a, b in pairs],
            "areas": [{"id": "P", "nodes": ["p"]}],
        }
    )


def test_a_closed_node_is_driven_around_when_another_way_exists() -> None:
    site = ring_site()
    graph = SiteGraph(site)
    assert graph.shortest_path("s", "g").nodes == ["s", "p", "g"]
    closed = closed_nodes(site, [closure("area", "P")], time.time())
    path = path_avoiding(graph, "s", "g", closed)
    assert path.nodes == ["s", "q1", "q2", "g"]
    assert path.length_m == pytest.approx(30.0)


def test_a_goal_only_closed_nodes_lead_to_is_refused_with_the_reason() -> None:
    site = line_site()
    graph = SiteGraph(site)
    closed = closed_nodes(site, [closure("area", "west")], time.time())
    with pytest.raises(RouteClosed) as cut:
        path_avoiding(graph, "w", "e", closed)
    assert cut.value.reason == "gallery west closed: cleaning"
    with pytest.raises(RouteClosed, match="gallery west closed"):
        path_avoiding(graph, "w", "x1", closed)
    # A robot standing inside a closed gallery gets out of it.
    assert path_avoiding(graph, "x1", "w", closed).nodes == ["x1", "w"]


def test_a_closure_between_two_times_closes_only_then() -> None:
    site = line_site()
    now = time.time()
    later = closure("nodes", nodes=["x2"], start=now + 60, end=now + 120)
    assert closed_nodes(site, [later], now) == {}
    assert set(closed_nodes(site, [later], now + 61)) == {"x2"}
    assert closed_nodes(site, [later], now + 121) == {}


def test_bad_closures_are_refused_with_a_clear_error() -> None:
    with pytest.raises(ValueError, match="needs a target"):
        ClosureRequest(kind="door", reason="x")
    with pytest.raises(ValueError, match="end must come after start"):
        ClosureRequest(kind="area", target="A", reason="x", start=10, end=5)
    with pytest.raises(ValueError, match="at least one node"):
        ClosureRequest(kind="nodes", reason="x")


def test_an_elevator_out_of_service_is_not_ridden() -> None:
    site = demo_site()
    graph = SiteGraph(site)
    elevator = site.elevators[0]
    across = graph.shortest_path("ga1", "gc3")
    assert any(s.elevator == elevator.id for s in across.steps)
    closed = closed_nodes(site, [closure("elevator", elevator.id)], time.time())
    with pytest.raises(RouteClosed, match=f"elevator {elevator.id} closed"):
        path_avoiding(graph, "ga1", "gc3", closed)


def test_only_a_device_failure_is_trouble() -> None:
    now = time.time()
    jam = trouble_of("open_door", "d1", "door d1 not open within 4 s", now, 120)
    assert jam is not None and jam.kind == "door" and jam.end == now + 120
    assert trouble_of("open_door", "d1", "fire alarm: door closed to robots", now, 120) is None
    assert trouble_of("open_door", "d1", "building interface busy (64 ...)", now, 120) is None
    stuck = trouble_of("call_elevator", "lift", "not confirmed: no progress for 14 s", now, 9)
    assert stuck is not None and stuck.kind == "elevator"


async def test_get_path_goes_around_a_closure_and_says_why_when_it_cannot() -> None:
    bus = Bus()
    site = line_site()
    traffic = await start_traffic(bus, site)
    service = ClosureService(bus.endpoint("closures"), lambda: site, None, None)
    traffic.closures = lambda: service.closed
    heard: list[dict[str, object]] = []
    bus.endpoint("console").subscribe("closures_changed", lambda m: heard.append(m.payload))
    await service.start()
    try:
        await service.add(ClosureRequest(kind="area", target="west", reason="wet floor"), by="ann")
        assert heard[-1]["nodes"] == ["x1"]
        robot = RobotStub(bus, "R1", "w")
        robot.state()
        reply = await robot.endpoint.request("get_path", {"robot": "R1", "to_node": "e"})
        assert reply.payload["closed"] is True
        assert reply.payload["reason"] == "gallery west closed: wet floor"
        assert reply.payload["trouble"] is False  # staff's closure: nothing to wait for
        reply = await robot.endpoint.request("get_path", {"robot": "R1", "to_node": "b"})
        assert reply.payload["nodes"] == ["w", "a", "b"]
        (only,) = service.closures
        await service.remove(only, by="bob")
        assert heard[-1]["nodes"] == []
        reply = await robot.endpoint.request("get_path", {"robot": "R1", "to_node": "e"})
        assert reply.payload["nodes"] == ["w", "x1", "x2", "e"]
    finally:
        await service.stop()
        await traffic.stop()


async def test_trouble_closes_a_door_or_a_lift_until_it_is_seen_working() -> None:
    bus = Bus()
    site = demo_site()
    service = ClosureService(bus.endpoint("closures"), lambda: site, None, None)
    await service.start()
    door = site.doors[0]
    try:
        building = bus.endpoint("building")
        building.publish(
            "command_failed",
            {
                "command": "open_door",
                "reason": f"door {door.id} not open within 4 s",
                "target": door.id,
            },
            destination="R1",
        )
        assert door.node in service.closed
        building.publish("door_opened", {"door": door.id})
        assert door.node not in service.closed
        # A lift that does not come: its stops are closed until the cabin is seen working.
        lift = site.elevators[0]
        building.publish(
            "command_failed",
            {
                "command": "call_elevator",
                "reason": "call not confirmed: the cabin showed no progress for 14 s",
                "target": lift.id,
            },
            destination="R2",
        )
        assert {s.node for s in lift.stops} <= set(service.closed)
        assert service.view()["closures"][0]["what"] == f"elevator {lift.id}"
        building.publish(
            "elevator_in_position", {"elevator": lift.id, "floor": "F1", "door_open": False}
        )
        assert lift.stops[0].node in service.closed  # a closed door is no sign of life
        building.publish(
            "elevator_in_position", {"elevator": lift.id, "floor": "F1", "door_open": True}
        )
        assert not service.closed
    finally:
        await service.stop()


async def test_a_jammed_door_is_held_closed_briefly_then_longer_while_it_keeps_failing() -> None:
    """Nobody sees a door work again while robots keep off it: a jam of a few seconds held it
    closed for the whole 120 s and tours skipped every stop behind it (30-minute fault soak).
    Its first failure holds it briefly; each failure in a row after that twice as long."""
    bus = Bus()
    site = demo_site()
    now = [1000.0]
    service = ClosureService(
        bus.endpoint("closures"), lambda: site, None, None, trouble_hold_s=120, clock=lambda: now[0]
    )
    await service.start()
    door = site.doors[0]
    key = f"trouble-door-{door.id}"
    first = 120 / FIRST_HOLD_PART  # 10 s
    building = bus.endpoint("building")

    def jammed() -> float:
        """The door fails a robot's open_door: how long it is held closed from now."""
        failed = {"command": "open_door", "reason": "not open within 4 s", "target": door.id}
        building.publish("command_failed", failed, destination="R1")
        end = service.closures[key].end
        assert end is not None and door.node in service.closed
        return end - now[0]

    def hold_ends(held: float) -> None:
        now[0] += held
        service.refresh()
        assert door.node not in service.closed

    try:
        assert jammed() == first
        now[0] += 2
        assert jammed() == first  # another robot, same outage: held on from now
        hold_ends(first)
        assert jammed() == 2 * first  # failed again at its next try
        hold_ends(2 * first)
        assert jammed() == 4 * first
        hold_ends(4 * first)
        assert jammed() == 8 * first
        hold_ends(8 * first)
        assert jammed() == 120  # never more than the longest hold
        building.publish("door_opened", {"door": door.id})
        assert door.node not in service.closed
        assert jammed() == first  # seen working: a first failure again
    finally:
        await service.stop()


async def test_a_door_and_a_lift_that_failed_only_for_their_modules_outage_reopen_with_it() -> None:
    """Issue 36 (the fault soak): a 7 s outage of otb_ground closed the gallery door and the
    lift for the whole trouble hold, as no robot asks a closed door to open and nobody saw
    them work. Its module back online, they reopen; a jammed door does not."""
    bus = Bus()
    site = demo_site()
    service = ClosureService(bus.endpoint("closures"), lambda: site, None, None)
    await service.start()
    gallery, upstairs = site.doors[0], site.doors[1]
    lift = site.elevators[0]
    outage = "module otb_ground is offline (cannot connect to 127.0.0.1:9)"
    try:
        building = bus.endpoint("building")
        for command, target, reason in (
            ("open_door", gallery.id, outage),
            ("call_elevator", lift.id, outage),
            ("open_door", upstairs.id, f"door {upstairs.id} not open within 7 s"),
        ):
            failed = {"command": command, "reason": reason, "target": target}
            building.publish("command_failed", failed, destination="R1")
        assert {gallery.node, upstairs.node, lift.stops[0].node} <= set(service.closed)
        building.publish("building_module_health", {"module": "otb_first", "online": True})
        building.publish("building_module_health", {"module": "otb_ground", "online": False})
        assert {gallery.node, lift.stops[0].node} <= set(service.closed)
        building.publish("building_module_health", {"module": "otb_ground", "online": True})
        assert set(service.closed) == {upstairs.node}
    finally:
        await service.stop()


async def test_a_robot_that_does_not_back_off_is_asked_again_then_another_backs_off() -> None:
    """A planted cycle: R2 is asked to yield east and never does (deaf or stuck). The guard
    asks it again, then has R1 back off from west instead, and R2 is granted west."""
    bus = Bus()
    events: list[tuple[str, dict[str, object]]] = []
    traffic = await start_traffic(bus, line_site(), events)
    traffic.cycle_break_s = 0.2
    try:
        r1, r2 = RobotStub(bus, "R1", "x1"), RobotStub(bus, "R2", "x2")
        await r1.endpoint.request("request_area", {"robot": "R1", "area": "west"})
        await r2.endpoint.request("request_area", {"robot": "R2", "area": "east"})
        r1.state("busy")
        r2.state("busy")
        r1.endpoint.publish("request_area", {"robot": "R1", "area": "east"})
        r2.endpoint.publish("request_area", {"robot": "R2", "area": "west"})
        await r2.wait_for("area_yield")  # the request-time rule: R2 backs off
        again = await r2.wait_for("area_yield", 2)  # not acted on: asked again
        assert again.payload["area"] == "east"
        order = await r1.wait_for("area_yield")  # still not: R1 backs off instead
        assert order.payload["area"] == "west"
        r1.node = "w"
        r1.state("busy")  # R1 leaves west
        grant = await r2.wait_for("area_granted", 2)
        assert grant.payload["area"] == "west"
        broken = [d for k, d in events if k == "wait_cycle_broken"]
        assert [sorted(d["cycle"]) for d in broken] == [["R1", "R2"], ["R1", "R2"]]
    finally:
        await traffic.stop()


async def test_closures_are_kept_across_restarts_and_bad_ones_refused(tmp_path: Path) -> None:
    """Staff close over REST (operators and admins only), the closure survives a restart,
    a planned one is not in force yet, a bad one is a 422 naming why, and reopening works."""
    settings = server_settings(tmp_path)
    staff = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
    later = time.time() + 3600
    async with (
        running_server(settings) as srv,
        httpx.AsyncClient(base_url=srv.url, headers=staff) as http,
    ):
        panel = await http.get("/api/closures", headers={"Authorization": f"Bearer {PANEL_TOKEN}"})
        assert panel.status_code == 403
        bad = await http.post(
            "/api/closures", json={"kind": "door", "target": "nope", "reason": "x"}
        )
        assert bad.status_code == 422 and "unknown door 'nope'" in bad.text
        bad = await http.post("/api/closures", json={"kind": "area", "reason": "x"})
        assert bad.status_code == 422 and "needs a target" in bad.text
        now = await http.post(
            "/api/closures", json={"kind": "elevator", "target": "lift", "reason": "service"}
        )
        assert now.status_code == 201, now.text
        planned = await http.post(
            "/api/closures",
            json={"kind": "nodes", "nodes": ["gb1"], "reason": "event", "start": later},
        )
        assert planned.json()["active"] is False
    async with (
        running_server(settings) as srv,
        httpx.AsyncClient(base_url=srv.url, headers=staff) as http,
    ):
        view = (await http.get("/api/closures")).json()
        assert [(c["what"], c["active"], c["by"]) for c in view["closures"]] == [
            ("elevator lift", True, "operator-1"),
            ("nodes gb1", False, "operator-1"),
        ]
        assert view["closed_nodes"] == ["lift0", "lift1"]
        path = await http.get("/api/paths?from_node=hall&to_node=gc1")
        assert path.status_code == 409
        assert path.json()["detail"] == "gc1 cut off: elevator lift closed: service"
        gone = await http.delete(f"/api/closures/{view['closures'][0]['id']}")
        assert gone.status_code == 200
        assert (await http.delete("/api/closures/nope")).status_code == 404
        assert (await http.get("/api/closures")).json()["closed_nodes"] == []
        events = (await http.get("/api/events?kind=closure_removed")).json()["events"]
        assert [(e["data"]["what"], e["data"]["by"]) for e in events] == [
            ("elevator lift", "operator-1")
        ]
