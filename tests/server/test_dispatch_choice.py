"""Issue 36's rules of robot choice as pure functions: idle robots take turns, a robot on
another floor pays its turn at the lift, a robot that cannot finish a tour on its battery is
not given it, the emptiest robots charge first, and a robot asking again for an area keeps its
place in line."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

from backend.tasks.charging import can_finish, finish_floor, learn_drain
from backend.tasks.choice import TURN_SLACK_S, choose_robot, idle_errands
from backend.tasks.lifts import DOORS_S, LiftWait, lift_queue
from backend.tasks.model import Task
from backend.tasks.robots import RobotInfo
from backend.traffic.locks import AreaLocks
from guidebot.site.graph import SiteGraph
from guidebot.site.schema import RobotConfig

from .helpers import demo_site


def robot(name: str, node: str | None, *, battery: float = 1.0) -> RobotInfo:
    config = RobotConfig(name=name, token="t" * 16, max_speed_mps=1.0)
    return RobotInfo(name, config, online=True, node=node, battery=battery)


def tour() -> Task:
    return Task("t1", "tour", {"tour": "main"}, 5, "panel", 1)


def test_idle_robots_take_turns_within_the_slack_the_nearest_otherwise() -> None:
    metres = {"hall": 10.0, "dock": 30.0, "far": 10.0 + TURN_SLACK_S + 5}
    worn, rested, distant = robot("R1", "hall"), robot("R2", "dock"), robot("R3", "far")
    worn.touring_s, rested.touring_s, distant.touring_s = 900.0, 100.0, 0.0
    free = {r.name: r for r in (worn, rested, distant)}
    # R2 is 20 s further than R1 but has toured less: its turn. R3 toured least but is beyond
    # the slack: a visitor does not wait a minute more for fairness.
    assert choose_robot(tour(), free, lambda: metres) is rested
    rested.touring_s = 900.0
    assert choose_robot(tour(), free, lambda: metres) is worn  # equal turns: the nearest


def test_a_robot_that_cannot_finish_the_tour_is_not_chosen() -> None:
    near, far = robot("R1", "hall", battery=0.4), robot("R2", "dock")
    metres = {"hall": 1.0, "dock": 200.0}
    free = {"R1": near, "R2": far}
    near.drain_per_s = 0.001  # 0.4 - 0.001 * 600 s < the finish floor
    chosen = choose_robot(tour(), free, lambda: metres, fits=lambda r: can_finish(r, 600.0))
    assert chosen is far
    assert (
        choose_robot(tour(), {"R1": near}, lambda: metres, fits=lambda r: can_finish(r, 600.0))
        is None
    )
    assert can_finish(near, 100.0)  # a short task it can
    assert finish_floor(near) == 0.2  # half-way between panic (0.1) and low (0.3)


def test_the_drain_is_learned_from_falling_readings_never_while_charging() -> None:
    r = robot("R1", "hall")
    learn_drain(r, 0.90, "busy", 0.0)
    learn_drain(r, 0.89, "busy", 2.0)  # too close to tell
    assert r.drain_per_s is None
    learn_drain(r, 0.80, "busy", 100.0)
    assert r.drain_per_s is not None and abs(r.drain_per_s - 0.001) < 1e-9
    learn_drain(r, 0.95, "charging", 200.0)
    learn_drain(r, 0.99, "idle", 300.0)  # a level that rose: a new start, nothing learned
    assert abs(r.drain_per_s - 0.001) < 1e-9
    assert can_finish(
        robot("R2", "hall", battery=0.25), 10_000.0
    )  # drain unknown: battery_low decides


def test_a_robot_on_another_floor_pays_for_its_turn_at_the_lift() -> None:
    site = demo_site()
    graph = SiteGraph(site)
    lifts = LiftWait(lambda: 3)
    lifts.site_changed(site)
    ride = max(e.travel_time_s for e in site.elevators)
    assert lifts.turn_s == 2 * ride + DOORS_S
    upstairs = next(n.id for n in site.nodes if n.floor != "F0")
    assert lifts.wait_s(graph, "hall", upstairs, lifts.queued()) == 3 * lifts.turn_s
    assert lifts.wait_s(graph, "hall", "entrance", lifts.queued()) == 0.0
    same_floor, other_floor = robot("R1", "hall"), robot("R2", upstairs)
    metres = {"hall": 40.0, upstairs: 30.0}  # R2 is nearer along the map, but behind the lift
    chosen = choose_robot(
        tour(),
        {"R1": same_floor, "R2": other_floor},
        lambda: metres,
        extra_cost=lambda r: lifts.wait_s(graph, r.node, "entrance", lifts.queued()),
    )
    assert chosen is same_floor


def test_the_lift_queue_counts_robots_holding_or_waiting_for_a_lift_area() -> None:
    site = demo_site()
    graph = SiteGraph(site)
    lift_area = next(graph.area_at[n] for n in graph.elevator_at if n in graph.area_at)
    others = [a.id for a in site.areas if a.id != lift_area]
    locks = AreaLocks([a.id for a in site.areas])
    locks.request("R1", [lift_area])
    locks.request("R2", [lift_area])
    locks.request("R3", [lift_area])
    if others:
        locks.request("R4", [others[0]])
    assert lift_queue(locks.view, lambda: graph)() == 3


def test_asking_again_for_the_lift_keeps_a_robots_place_in_line() -> None:
    locks = AreaLocks(["lift"])
    locks.request("R1", ["lift"])  # holds it
    locks.request("R2", ["lift"])
    locks.request("R3", ["lift"])
    locks.request("R2", ["lift"])  # R2 asks again (a re-ask, a reconnect)
    [view] = locks.view()
    assert view.waiting == ["R2", "R3"]
    [grant] = locks.release("R1", "lift")
    assert grant.robot == "R2"


def test_the_emptiest_robots_charge_first_and_a_waiting_robot_charges_when_it_can() -> None:
    site: Any = SimpleNamespace(
        charging_stations=[SimpleNamespace(id="s1", node="dock1")],
        wait_points=[SimpleNamespace(node="lobby")],
    )
    metres = {
        "dock1": {"hall": 5.0, "cafe": 50.0, "lobby": 3.0},
        "lobby": {"hall": 1.0, "cafe": 1.0},
    }
    full, empty = robot("R1", "hall", battery=0.9), robot("R2", "cafe", battery=0.35)
    found = idle_errands(
        [full, empty], [full, empty], (), site, metres.__getitem__, lambda r: False
    )
    assert [(r.name, kind) for r, kind, _ in found] == [("R2", "charge"), ("R1", "go_to")]
    waiting = robot("R3", "lobby", battery=0.5)  # idle at the wait point, half empty
    found = idle_errands([waiting], [waiting], (), site, metres.__getitem__, lambda r: False)
    assert [(r.name, kind) for r, kind, _ in found] == [("R3", "charge")]
    waiting.battery = 0.9  # above the opportunistic threshold: it stays
    assert idle_errands([waiting], [waiting], (), site, metres.__getitem__, lambda r: False) == []
