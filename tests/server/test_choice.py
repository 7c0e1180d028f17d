"""The Task Manager's robot choice as pure functions (backend/tasks/choice.py)."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from backend.tasks.choice import (
    BATTERY_WEIGHT_S,
    UNKNOWN_POSITION_COST_S,
    available,
    choose_robot,
    idle_errands,
    nearest,
    robot_cost,
)
from backend.tasks.model import InvalidTask, Task
from backend.tasks.robots import RobotInfo
from guidebot.site.schema import RobotConfig


def robot(name: str, node: str | None, *, battery: float = 1.0, speed: float = 1.0) -> RobotInfo:
    config = RobotConfig(name=name, token="t" * 16, max_speed_mps=speed)
    return RobotInfo(name, config, online=True, node=node, battery=battery)


def tour(**fields: object) -> Task:
    return Task("t1", "tour", {"tour": "main"}, 5, "panel", 1, **fields)  # type: ignore[arg-type]


METRES = {"hall": 10.0, "cafe": 40.0}


def test_the_cheapest_robot_wins_battery_counting_as_seconds() -> None:
    near_but_flat = robot("R1", "hall", battery=0.0)  # 10 s + 120 s
    far_but_full = robot("R2", "cafe")  # 40 s
    free = {r.name: r for r in (near_but_flat, far_but_full)}
    assert choose_robot(tour(), free, lambda: METRES) is far_but_full
    assert robot_cost(near_but_flat, 10.0) == 10.0 + BATTERY_WEIGHT_S
    assert robot_cost(robot("R3", None), None) == UNKNOWN_POSITION_COST_S


def test_the_robot_a_task_was_taken_from_only_when_no_other_is_free() -> None:
    returning = robot("R1", "hall")
    other = robot("R2", "cafe")
    free = {"R1": returning, "R2": other}
    assert choose_robot(tour(), free, lambda: METRES, rather_not={"R1"}) is other
    assert choose_robot(tour(), {"R1": returning}, lambda: METRES, rather_not={"R1"}) is returning
    assert choose_robot(tour(), free, lambda: METRES, avoid={"R1", "R2"}) is None


def test_a_pinned_task_waits_for_its_robot_and_never_asks_for_distances() -> None:
    def no_distances() -> dict[str, float]:
        raise InvalidTask("not needed")

    r1 = robot("R1", "hall")
    assert choose_robot(tour(pinned_robot="R1"), {"R1": r1}, no_distances) is r1
    assert choose_robot(tour(pinned_robot="R9"), {"R1": r1}, no_distances) is None
    r1.out_of_service = True
    assert choose_robot(tour(pinned_robot="R1"), {"R1": r1}, no_distances) is None
    go_to = Task("t2", "go_to", {"node": "hall"}, 5, "staff", 2, pinned_robot="R1")
    assert choose_robot(go_to, {"R1": r1}, no_distances) is r1  # staff may still move it
    with pytest.raises(InvalidTask):
        choose_robot(tour(), {"R1": r1}, no_distances)


def test_available_means_online_sound_charged_and_free_of_main_tasks() -> None:
    r = robot("R1", "hall")
    assert available(r, None)
    r.current = "t1"
    assert not available(r, tour())
    assert available(r, tour(internal=True))
    r.current = None
    r.battery = r.config.battery_low
    assert not available(r, None)
    r.battery, r.fault = 1.0, True
    assert not available(r, None)


def test_nearest_place_with_unreachable_ones_last() -> None:
    places = [
        SimpleNamespace(node="far"),
        SimpleNamespace(node="island"),
        SimpleNamespace(node="near"),
    ]
    table = {"far": {"hall": 50.0}, "island": {}, "near": {"hall": 5.0}}
    assert nearest("hall", places, lambda node: table[node]) is places[2]
    assert nearest("hall", places[1:2], lambda node: table[node]) is places[1]
    assert nearest("hall", [], lambda node: table[node]) is None


def test_idle_robots_charge_at_a_free_station_else_wait_and_stay_where_they_belong() -> None:
    site: Any = SimpleNamespace(
        charging_stations=[
            SimpleNamespace(id="s1", node="dock1"),
            SimpleNamespace(id="s2", node="dock2"),
        ],
        wait_points=[SimpleNamespace(node="lobby")],
    )
    metres = {"dock1": {"hall": 5.0, "cafe": 50.0}, "dock2": {"hall": 9.0, "cafe": 8.0}}
    metres["lobby"] = {"hall": 1.0, "cafe": 1.0}
    hall, cafe, docked = robot("R1", "hall"), robot("R2", "cafe"), robot("R3", "dock2")
    waiting, low = robot("R4", "lobby"), robot("R5", "dock1")
    low.needs_charge = True

    def errands(idle: list[RobotInfo], charging_at: tuple[str, ...] = ()) -> list[object]:
        fleet = [hall, cafe, docked, waiting, low]
        found = idle_errands(idle, fleet, charging_at, site, metres.__getitem__, lambda r: False)
        return [(r.name, kind, params) for r, kind, params in found]

    # Both stations are taken (R3 and R5 stand on them): to the wait point; R4 is there already.
    assert errands([hall, waiting]) == [("R1", "go_to", {"node": "lobby"})]
    # A robot needing charge on its station charges there; one already charging stays.
    assert errands([low]) == [("R5", "charge", {"station": "s1"})]
    low.mode = "charging"
    assert errands([low]) == []
    # A station is free when nobody stands on it or holds a charge task for it.
    docked.node, low.node = "hall", "cafe"
    assert errands([hall, cafe], charging_at=("s1",)) == [
        ("R1", "charge", {"station": "s2"}),
        ("R2", "go_to", {"node": "lobby"}),
    ]
    # Offline, faulty or out-of-service robots, and robots with queued work, go nowhere.
    hall.online = False
    assert errands([hall]) == []
    found = idle_errands([cafe], [cafe], (), site, metres.__getitem__, lambda r: True)
    assert found == []
