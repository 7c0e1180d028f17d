"""The Task Manager's robot choice as pure functions (backend/tasks/choice.py)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from backend.tasks.choice import (
    BATTERY_WEIGHT_S,
    UNKNOWN_POSITION_COST_S,
    available,
    choose_robot,
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
