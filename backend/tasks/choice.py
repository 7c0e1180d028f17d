"""Which robot gets a task, and which place suits an idle robot: pure functions of what the
Task Manager knows (robots, the task, distances over the site graph), no bus and no clock,
so the rules can be read and tested on their own (docs/server.md "Assignment")."""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterable, Mapping
from typing import Protocol, TypeVar

from backend.tasks.model import Task
from backend.tasks.robots import RobotInfo
from guidebot.task_kinds import MANUAL_KINDS

__all__ = [
    "BATTERY_WEIGHT_S",
    "MANUAL_KINDS",
    "UNKNOWN_POSITION_COST_S",
    "Distances",
    "available",
    "choose_robot",
    "nearest",
    "robot_cost",
]

BATTERY_WEIGHT_S = 120.0
"""Cost in seconds of an empty battery when ranking robots (a full one costs nothing)."""
UNKNOWN_POSITION_COST_S = 3600.0

P = TypeVar("P")


class Distances(Protocol):
    """Metres from each node to one target (``SiteGraph.distances_to``); None: unreachable."""

    def get(self, node: str | None, /) -> float | None: ...


def available(robot: RobotInfo, current: Task | None) -> bool:
    """Free for a main task: online, sound, charged enough, doing nothing or an internal task
    (``current``: the task it holds, None if it holds none or one no longer known)."""
    if not robot.online or robot.fault or robot.needs_charge:
        return False
    if robot.battery <= robot.config.battery_low:
        return False
    return robot.current is None or current is None or current.internal


def robot_cost(robot: RobotInfo, metres: float | None) -> float:
    """Seconds to reach the task's start at the robot's speed, plus a battery penalty."""
    travel = metres / robot.config.max_speed_mps if metres is not None else UNKNOWN_POSITION_COST_S
    return travel + (1.0 - robot.battery) * BATTERY_WEIGHT_S


def choose_robot(
    task: Task,
    free: Mapping[str, RobotInfo],
    distances: Callable[[], Distances],
    *,
    avoid: Collection[str] = (),
    rather_not: Collection[str] = (),
) -> RobotInfo | None:
    """The robot for ``task`` among ``free`` ones, None if none fits.

    A pinned task takes its robot or waits. Otherwise the cheapest (``robot_cost``) robot not
    in ``avoid`` nor out of service; one in ``rather_not`` (the task was taken from it) only
    if no other is free now, so a visitor never waits for a busy robot while the returning one
    stands idle. ``distances()`` (node -> metres to the task's start) is only called when the
    task is not pinned; it may raise TaskError.
    """
    if task.pinned_robot is not None:
        robot = free.get(task.pinned_robot)
        if robot is not None and robot.out_of_service and task.kind not in MANUAL_KINDS:
            return None
        return robot
    dist = distances()
    best: RobotInfo | None = None
    best_cost = math.inf
    best_is_fallback = True
    for robot in free.values():
        if robot.name in avoid or robot.out_of_service:
            continue
        fallback = robot.name in rather_not
        cost = robot_cost(robot, dist.get(robot.node) if robot.node is not None else None)
        if (best_is_fallback and not fallback) or (
            fallback == best_is_fallback and cost < best_cost
        ):
            best, best_cost, best_is_fallback = robot, cost, fallback
    return best


def nearest(
    node: str | None, places: Iterable[P], distances_to: Callable[[str], Distances]
) -> P | None:
    """The place (anything with a ``node``) closest to ``node``; unreachable ones last, the
    first listed among equals; None if there are no places."""
    best: P | None = None
    best_cost = math.inf
    for place in places:
        found = distances_to(place.node).get(node)  # type: ignore[attr-defined]
        dist = math.inf if found is None else found
        if best is None or dist < best_cost:
            best, best_cost = place, dist
    return best
