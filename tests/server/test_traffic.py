"""Traffic Manager over a real bus: paths across floors, area locks, no deadlock."""

from __future__ import annotations

import time
from typing import Any

import pytest
from pydantic import ValidationError

from backend.traffic import LockState, TrafficManager
from backend.traffic.locks import AreaLocks, Grant
from guidebot.bus import Bus
from guidebot.payloads.traffic import Path
from guidebot.site import Site, validate_site
from guidebot.site.graph import NoPath, SiteGraph, UnknownNode
from guidebot.site.steps import PathStep

from .helpers import RobotStub, demo_site


def line_site() -> Site:
    """w - x1 - x2 - e (a narrow corridor split in two areas) and a loop of three areas."""
    nodes: list[dict[str, Any]] = [
        {"id": "w", "floor": "F0", "x": 0, "y": 0, "passing_place": True},
        {"id": "x1", "floor": "F0", "x": 5, "y": 0},
        {"id": "x2", "floor": "F0", "x": 10, "y": 0},
        {"id": "e", "floor": "F0", "x": 15, "y": 0, "passing_place": True},
        {"id": "a", "floor": "F0", "x": 0, "y": 20},
        {"id": "b", "floor": "F0", "x": 10, "y": 20},
        {"id": "c", "floor": "F0", "x": 5, "y": 30},
    ]
    return validate_site(
        {
            "name": "line",
            "floors": [{"id": "F0"}],
            "nodes": nodes,
            "edges": [
                {"a": "w", "b": "x1"},
                {"a": "x1", "b": "x2"},
                {"a": "x2", "b": "e"},
                {"a": "a", "b": "b"},
                {"a": "b", "b": "c"},
                {"a": "c", "b": "a"},
                {"a": "a", "b": "w"},
            ],
            "areas": [
                {"id": "west", "nodes": ["x1"]},
                {"id": "east", "nodes": ["x2"]},
                {"id": "A", "nodes": ["a"], "passing_place": "w"},
                {"id": "B", "nodes": ["b"], "passing_place": "w"},
                {"id": "C", "nodes": ["c"], "passing_place": "w"},
            ],
            "robots": [{"name": n, "token": f"token-{n}-xxxx"} for n in ("R1", "R2", "R3")],
        }
    )


@pytest.fixture
def bus() -> Bus:
    return Bus()


async def start_traffic(
    bus: Bus, site: Site, events: list[tuple[str, dict[str, Any]]] | None = None
) -> TrafficManager:
    """A started Traffic Manager; what it logs is appended to ``events``."""
    log = events.append if events is not None else None
    manager = TrafficManager(
        bus.endpoint("traffic_manager"),
        site,
        on_event=(lambda kind, data: log((kind, data))) if log is not None else None,
    )
    await manager.start()
    return manager


def test_path_across_floors_goes_through_the_elevator_and_names_doors() -> None:
    graph = SiteGraph(demo_site())
    path = graph.shortest_path("ga1", "gc3")
    assert path.nodes[:3] == ["ga1", "door_hall", "hall"]
    assert ["lift0", "lift1"] == path.nodes[3:5]
    steps = {s.node: s for s in path.steps}
    assert steps["door_hall"].door == "door_gallery"
    assert steps["door_f1"].door == "door_upstairs"
    assert steps["lift0"].elevator == "lift" and steps["lift1"].floor == "F1"
    assert path.areas == ["elevator"]


def test_a_path_step_is_one_type_from_graph_to_message_to_robot() -> None:
    """The graph's steps go out in the ``path`` payload and come back on the robot as the
    same PathStep; a step without its floor or coordinates is refused."""
    path = SiteGraph(demo_site()).shortest_path("ga1", "gc3")
    wire = Path(nodes=path.nodes, steps=path.steps).model_dump(mode="json")
    assert Path.model_validate(wire).steps == path.steps
    assert [PathStep.from_dict(s) for s in wire["steps"]] == path.steps
    with pytest.raises(KeyError):
        PathStep.from_dict({"node": "ga1", "x": 0, "y": 0})
    with pytest.raises(ValidationError, match="floor"):
        Path.model_validate({"steps": [{"node": "ga1", "x": 0, "y": 0}]})


def test_one_way_edges_are_respected() -> None:
    graph = SiteGraph(demo_site())
    back = graph.shortest_path("gb2", "ga2")  # the back gallery is one-way east to west
    assert back.nodes == ["gb2", "ga2"]
    forth = graph.shortest_path("ga2", "gb2")
    assert forth.nodes == ["ga2", "ga1", "corridor_w", "corridor_e", "gb1", "gb2"]
    assert forth.areas == ["corridor"]


def test_unknown_nodes_and_unreachable_targets_are_errors() -> None:
    site = demo_site()
    doc = site.model_dump(mode="json")
    doc["nodes"].append({"id": "island", "floor": "F0", "x": 99, "y": 99})
    graph = SiteGraph(validate_site(doc))
    with pytest.raises(UnknownNode):
        graph.shortest_path("hall", "nowhere")
    with pytest.raises(NoPath):
        graph.shortest_path("hall", "island")


async def test_get_path_is_answered_over_the_bus(bus: Bus) -> None:
    await start_traffic(bus, demo_site())
    robot = bus.endpoint("R1")
    ask = {"robot": "R1", "from_node": "entrance", "to_node": "gc3"}
    reply = await robot.request("get_path", ask)
    assert reply.type == "path" and reply.payload["nodes"][0] == "entrance"
    assert reply.payload["steps"][-1]["node"] == "gc3"
    bad = await robot.request("get_path", {"robot": "R1", "from_node": "entrance", "to_node": "x"})
    assert bad.payload.get("error") and not bad.payload.get("nodes")


async def test_a_node_reached_sent_again_late_never_moves_the_robot_back(bus: Bus) -> None:
    """node_reached is must-arrive: one the server died before handling comes again after
    the restart, behind newer reports. The robot is where its latest report (by the robot's
    time) says, not where the late copy does: paths start there."""
    await start_traffic(bus, demo_site())
    r1 = RobotStub(bus, "R1", "gb1")
    r1.state("busy")  # now, at gb1
    then = time.time() - 5.0
    r1.endpoint.publish("node_reached", {"robot": "R1", "node": "ga1", "floor": "F0", "at": then})
    ask = {"robot": "R1", "to_node": "hall"}
    reply = await r1.endpoint.request("get_path", ask)
    assert reply.payload["nodes"][0] == "gb1"
    r1.endpoint.publish("node_reached", {"robot": "R1", "node": "corridor_e", "at": time.time()})
    reply = await r1.endpoint.request("get_path", ask)
    assert reply.payload["nodes"][0] == "corridor_e"  # a newer one moves it on


async def test_waiting_robots_are_served_in_order(bus: Bus) -> None:
    traffic = await start_traffic(bus, demo_site())
    r1, r2, r3 = (RobotStub(bus, n, "ga1") for n in ("R1", "R2", "R3"))
    for robot in (r1, r2, r3):
        robot.endpoint.publish("request_area", {"robot": robot.name, "area": "corridor"})
    await r1.wait_for("area_granted")
    assert not r2.of_type("area_granted") and not r3.of_type("area_granted")
    assert traffic.lock_views()[0].waiting == ["R2", "R3"]
    r1.endpoint.publish("release_area", {"robot": "R1", "area": "corridor"})
    await r2.wait_for("area_granted")
    assert not r3.of_type("area_granted")
    r2.endpoint.publish("release_area", {"robot": "R2", "area": "corridor"})
    grant = await r3.wait_for("area_granted")
    assert grant.payload == {"robot": "R3", "area": "corridor", "removed": False, "reason": ""}


async def test_a_grant_answers_the_request_it_belongs_to(bus: Bus) -> None:
    await start_traffic(bus, demo_site())
    robot = RobotStub(bus, "R1", "ga1")
    reply = await robot.endpoint.request("request_area", {"robot": "R1", "area": "corridor"})
    assert reply.type == "area_granted"


async def test_robot_may_not_ask_or_release_for_another(bus: Bus) -> None:
    traffic = await start_traffic(bus, demo_site())
    r1 = RobotStub(bus, "R1", "ga1")
    reply = await r1.endpoint.request("request_area", {"robot": "R2", "area": "corridor"})
    assert reply.type == "error"
    await r1.endpoint.request("request_area", {"robot": "R1", "area": "corridor"})
    r2 = RobotStub(bus, "R2", "ga1")
    reply = await r2.endpoint.request("release_area", {"robot": "R1", "area": "corridor"})
    assert reply.type == "error"
    assert traffic.locks.holder("corridor") == "R1"
    reply = await r1.endpoint.request("request_area", {"robot": "R1", "area": "no_such_area"})
    assert reply.type == "error" and "unknown area" in reply.payload["reason"]


async def test_lock_is_released_when_the_robot_leaves_the_area(bus: Bus) -> None:
    traffic = await start_traffic(bus, demo_site())
    r1, r2 = RobotStub(bus, "R1", "ga1"), RobotStub(bus, "R2", "gb1")
    r1.endpoint.publish("request_area", {"robot": "R1", "area": "corridor"})
    r2.endpoint.publish("request_area", {"robot": "R2", "area": "corridor"})
    await r1.wait_for("area_granted")
    for node in ("ga1", "corridor_w", "corridor_e"):
        r1.node = node
        r1.state("busy")
    assert traffic.locks.holder("corridor") == "R1"  # still inside
    r1.node = "gb1"
    r1.state("busy")
    await r2.wait_for("area_granted")


async def test_offline_holder_keeps_its_lock_until_staff_release_it(bus: Bus) -> None:
    traffic = await start_traffic(bus, demo_site())
    r1, r2 = RobotStub(bus, "R1", "corridor_w"), RobotStub(bus, "R2", "gb1")
    await r1.endpoint.request("request_area", {"robot": "R1", "area": "corridor"})
    r1.state("busy")
    r1.state("offline")
    r2.endpoint.publish("request_area", {"robot": "R2", "area": "corridor"})
    view = next(v for v in traffic.lock_views() if v.area == "corridor")
    assert view.state is LockState.HOLDER_OFFLINE and view.holder == "R1"
    assert view.waiting == ["R2"] and not r2.of_type("area_granted")
    assert traffic.force_release("corridor", by="staff") == "R1"
    await r2.wait_for("area_granted")


async def test_task_end_releases_locks_except_the_area_the_robot_stands_in(bus: Bus) -> None:
    traffic = await start_traffic(bus, demo_site())
    r1 = RobotStub(bus, "R1", "corridor_e")
    await r1.endpoint.request("request_area", {"robot": "R1", "area": "corridor"})
    await r1.endpoint.request("request_area", {"robot": "R1", "area": "elevator"})
    r1.state("busy")
    # A task it refused (busy with this one) is not the end of what it runs: locks stay.
    r1.end("t2", outcome="refused", reason="robot busy with task t1")
    assert traffic.locks.held_by("R1") == ["corridor", "elevator"]
    r1.end("t1")
    assert traffic.locks.held_by("R1") == ["corridor"]


async def test_head_on_with_known_paths_is_prevented(bus: Bus) -> None:
    traffic = await start_traffic(bus, line_site())
    r1, r2 = RobotStub(bus, "R1", "w"), RobotStub(bus, "R2", "e")
    await r1.endpoint.request("get_path", {"robot": "R1", "from_node": "w", "to_node": "e"})
    await r2.endpoint.request("get_path", {"robot": "R2", "from_node": "e", "to_node": "w"})
    r1.endpoint.publish("request_area", {"robot": "R1", "area": "west"})
    r2.endpoint.publish("request_area", {"robot": "R2", "area": "east"})
    await r1.wait_for("area_granted", 2)  # west and east at once: the chain
    assert {m.payload["area"] for m in r1.of_type("area_granted")} == {"west", "east"}
    assert not r2.of_type("area_granted")
    for node in ("x1", "x2", "e"):
        r1.node = node
        r1.state("busy")
    await r2.wait_for("area_granted", 2)
    assert not r1.of_type("area_yield") and not r2.of_type("area_yield")
    assert traffic.locks.deadlocks_resolved == 0


async def test_head_on_without_paths_is_detected_and_one_robot_backs_off(bus: Bus) -> None:
    traffic = await start_traffic(bus, line_site())
    r1, r2 = RobotStub(bus, "R1", "x1"), RobotStub(bus, "R2", "x2")
    await r1.endpoint.request("request_area", {"robot": "R1", "area": "west"})
    await r2.endpoint.request("request_area", {"robot": "R2", "area": "east"})
    r1.state("busy")
    r2.state("busy")
    r1.endpoint.publish("request_area", {"robot": "R1", "area": "east"})
    r2.endpoint.publish("request_area", {"robot": "R2", "area": "west"})
    order = await r2.wait_for("area_yield")
    assert order.payload == {"robot": "R2", "area": "east", "go_to_node": "e"}
    assert traffic.locks.deadlocks_resolved == 1
    r2.node = "e"
    r2.state("busy")  # backed off: leaving the area releases it
    await r1.wait_for("area_granted", 2)
    assert traffic.locks.holder("east") == "R1"


async def test_three_robots_in_a_circle_all_get_through(bus: Bus) -> None:
    traffic = await start_traffic(bus, line_site())
    robots = [RobotStub(bus, "R1", "a"), RobotStub(bus, "R2", "b"), RobotStub(bus, "R3", "c")]
    held = ["A", "B", "C"]
    for robot, area in zip(robots, held, strict=True):
        await robot.endpoint.request("request_area", {"robot": robot.name, "area": area})
        robot.state("busy")
    for robot, area in zip(robots, ["B", "C", "A"], strict=True):
        robot.endpoint.publish("request_area", {"robot": robot.name, "area": area})
    r1, r2, r3 = robots
    order = await r3.wait_for("area_yield")
    assert order.payload["area"] == "C" and order.payload["go_to_node"] == "w"
    assert traffic.locks.wait_for_graph() == {"R1": {"R2"}, "R2": {"R3"}}
    r3.node = "w"
    r3.state("busy")
    await r2.wait_for("area_granted", 2)  # C
    r2.node = "c"
    r2.state("busy")  # leaves B
    await r1.wait_for("area_granted", 2)  # B
    r1.node = "b"
    r1.state("busy")  # leaves A
    r3.endpoint.publish("request_area", {"robot": "R3", "area": "A"})
    await r3.wait_for("area_granted", 2)
    assert traffic.locks.wait_for_graph() == {}


def test_the_planner_never_crosses_a_cabin_without_riding() -> None:
    """Even for a site that skipped the check, a cabin node is entered only to ride."""
    data = demo_site().model_dump(mode="json")
    # lift0 as a shortcut between charge_b and hall would save 2 m.
    data["edges"].append({"a": "charge_b", "b": "lift0"})
    site = Site.model_validate(data)
    path = SiteGraph(site).shortest_path("charge_b", "hall")
    assert "lift0" not in path.nodes
    assert path.nodes == ["charge_b", "charge_a", "entrance", "hall"]
    up = SiteGraph(site).shortest_path("hall", "gc1")
    assert up.nodes[:3] == ["hall", "lift0", "lift1"]


async def test_a_restarted_server_takes_back_the_locks_robots_report(bus: Bus) -> None:
    """The lock table starts empty after a restart: a robot inside an area, or holding a grant
    it has not used yet, keeps it from its robot_state; a second robot waits (found by the
    soak: both were once granted the elevator)."""
    events: list[tuple[str, dict[str, Any]]] = []
    traffic = await start_traffic(bus, demo_site(), events)
    r1, r2 = RobotStub(bus, "R1", "corridor_w"), RobotStub(bus, "R2", "hall")
    r3 = RobotStub(bus, "R3", "ga1")
    r1.state("busy")  # inside the corridor: nobody else held it
    r2.state("busy", areas=["elevator"])  # granted before the restart, not entered yet
    assert traffic.locks.holder("corridor") == "R1" and traffic.locks.entered("corridor")
    assert traffic.locks.holder("elevator") == "R2" and not traffic.locks.entered("elevator")
    assert ("area_granted", {"robot": "R2", "area": "elevator", "resync": True}) in events
    r3.endpoint.publish("request_area", {"robot": "R3", "area": "elevator"})
    r3.state("busy", areas=["corridor"])  # a stale claim on a held area is not taken
    assert traffic.locks.holder("corridor") == "R1" and not r3.of_type("area_granted")
    r2.node = "lift0"
    r2.state("busy", areas=["elevator"])
    r2.node = "hall"
    r2.state("busy", areas=[])  # out again: released, and the waiter gets it
    await r3.wait_for("area_granted")
    # Only a robot's first word after the start counts: later the table is the truth, and a
    # grant a robot still lists after its task ended is not taken back (the soak saw one
    # claim the corridor for ever).
    r2.state("idle", areas=["corridor", "elevator"])
    assert traffic.locks.holder("corridor") == "R1"
    assert traffic.locks.holder("elevator") == "R3"
    r1.node = "gb1"
    r1.state("idle", areas=["corridor"])
    assert traffic.locks.holder("corridor") is None


async def test_after_a_restart_no_area_is_granted_before_the_robots_that_had_tasks_resync(
    bus: Bus,
) -> None:
    """R4 was inside the corridor when the server died; R1 came back first and asked for it.
    It must wait for R4's word (found by the soak: both drove in)."""
    traffic = await start_traffic(bus, demo_site())
    r1, r2 = RobotStub(bus, "R1", "ga1"), RobotStub(bus, "R2", "corridor_e")
    traffic.await_resync({"R2", "R3"}, timeout_s=30)
    r1.state("busy")
    r1.endpoint.publish("request_area", {"robot": "R1", "area": "corridor"})
    r2.state("busy", areas=["corridor"])  # R2 back: it is inside and holds it
    assert traffic.locks.holder("corridor") == "R2"
    RobotStub(bus, "R3", "hall").state("idle")  # the last one: R1's request is handled now
    assert traffic.locks.waiting_for("R1") == ("corridor",) and not r1.of_type("area_granted")
    r2.node = "gb1"
    r2.state("busy", areas=[])
    await r1.wait_for("area_granted")
    await traffic.stop()


async def test_the_resync_wait_ends_without_a_robot_that_never_comes_back(bus: Bus) -> None:
    traffic = await start_traffic(bus, demo_site())
    traffic.await_resync({"R3"}, timeout_s=0.3)
    r1 = RobotStub(bus, "R1", "ga1")
    r1.endpoint.publish("request_area", {"robot": "R1", "area": "corridor"})
    assert not r1.of_type("area_granted")
    await r1.wait_for("area_granted", timeout=10)
    await traffic.stop()


async def test_a_restarted_server_holds_the_last_lives_locks_until_their_robots_report(
    bus: Bus,
) -> None:
    """R2 was in the lift when the server died and its link is still down when the resync
    window ends: the lift stays R2's (restored from the event log), R1 waits. R2's word from
    outside releases it (docs/server.md: locks come back from the event log)."""
    events: list[tuple[str, dict[str, Any]]] = []
    traffic = await start_traffic(bus, demo_site(), events)
    traffic.restore_locks({"elevator": "R2", "corridor": "R3", "nowhere": "R2", "stairs": "R99"})
    assert ("area_granted", {"robot": "R2", "area": "elevator", "restored": True}) in events
    views = {v.area: v for v in traffic.lock_views()}
    assert views["elevator"].holder == "R2" and views["elevator"].state == "holder_offline"
    r1 = RobotStub(bus, "R1", "hall")
    r1.state("busy")
    r1.endpoint.publish("request_area", {"robot": "R1", "area": "elevator"})
    assert not r1.of_type("area_granted")
    traffic.check_offline_locks(grace_s=0.0)  # it may be inside: kept, staff alerted
    assert traffic.locks.holder("elevator") == "R2"
    assert traffic.alerts.is_active("lock_holder_offline", "elevator")
    r3 = RobotStub(bus, "R3", "corridor_w")
    r3.state("busy", areas=["corridor"])  # inside: still its own
    assert traffic.locks.holder("corridor") == "R3"
    r2 = RobotStub(bus, "R2", "landing")
    r2.state("idle")  # back, outside the lift: released, and R1 gets it
    await r1.wait_for("area_granted")
    assert traffic.locks.holder("elevator") == "R1"
    await traffic.stop()


def test_a_robot_never_waits_on_itself_behind_an_earlier_waiters_claim() -> None:
    """Issue 36: R1 stands in corridor a (kept after its task, or by its restarted agent); R2,
    earlier, waits for a and the b after it. Without the two exceptions to the claim rule R1
    would wait behind R2, which waits for R1: a deadlock the wait-for graph does not show."""
    locks = AreaLocks(["a", "b"])
    assert locks.request("R1", ["a"])[0] == [Grant("R1", "a", None)]
    assert locks.request("R2", ["a", "b"], "r2") == ([], [])
    # Asking again for the area it holds: answered at once, said to be no new grant (a log
    # that counts grants, as the cluster test does, must not count it twice).
    assert locks.request("R1", ["a"], "again")[0] == [Grant("R1", "a", "again", again=True)]
    # Asking for b, to get out: R2's claim on b does not hold back the robot R2 waits on.
    assert locks.request("R1", ["b"], "out")[0] == [Grant("R1", "b", "out")]
    assert locks.release_all("R1") == [Grant("R2", "a", "r2"), Grant("R2", "b", "r2")]
    # Others are served in request order, as before.
    assert locks.request("R3", ["a"], "r3") == ([], [])
    assert locks.request("R4", ["a", "b"]) == ([], [])
    assert locks.release("R2", "a") == [Grant("R3", "a", "r3")]
