"""Which robot gets a task, and where an idle robot goes: pure functions of what the
Task Manager knows (robots, the task, distances over the site graph), no bus and no clock,
so the rules can be read and tested on their own (docs/server.md "Assignment")."""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterable, Mapping
from typing import Any, Protocol, TypeVar

from backend.tasks.model import Task
from backend.tasks.robots import RobotInfo
from guidebot.site.schema import Site
from guidebot.task_kinds import MANUAL_KINDS

__all__ = [
    "BATTERY_WEIGHT_S",
    "MANUAL_KINDS",
    "OPPORTUNISTIC_BELOW",
    "TURN_SLACK_S",
    "UNKNOWN_POSITION_COST_S",
    "Distances",
    "Errand",
    "available",
    "choose_robot",
    "idle_errands",
    "nearest",
    "robot_cost",
]

BATTERY_WEIGHT_S = 120.0
"""Cost in seconds of an empty battery when ranking robots (a full one costs nothing)."""
UNKNOWN_POSITION_COST_S = 3600.0
OPPORTUNISTIC_BELOW = 0.8
"""An idle robot at a wait point below this level goes to charge when a station is free."""
TURN_SLACK_S = 60.0
"""Turn taking: a robot up to this many seconds costlier than the cheapest may get a task in
its stead when it has toured less (a visitor waits at most this much more for fairness)."""

P = TypeVar("P")


class Distances(Protocol):
    """Metres from each node to one target (``SiteGraph.distances_to``); None: unreachable."""

    def get(self, node: str | None, /) -> float | None: ...


def available(robot: RobotInfo, current: Task | None) -> bool:
    """Free for a main task: online, sound, charged enough, doing nothing or an internal task
    (``current``: the task it holds, None if it holds none or one no longer known)."""
    if not robot.online or robot.fault or robot.needs_charge or robot.refused:
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
    extra_cost: Callable[[RobotInfo], float] | None = None,
    fits: Callable[[RobotInfo], bool] | None = None,
) -> RobotInfo | None:
    """The robot for ``task`` among ``free`` ones, None if none fits.

    A pinned task takes its robot or waits. Otherwise the cheapest (``robot_cost`` plus
    ``extra_cost``: the wait for the lift to another floor) robot not in ``avoid`` nor out of
    service, and able to finish it on its battery (``fits``); one in ``rather_not`` (the task
    was taken from it) only if no other is free now, so a visitor never waits for a busy robot
    while the returning one stands idle. Idle robots take turns: among the robots within
    ``TURN_SLACK_S`` of the cheapest, the one that has toured least (``touring_s``) gets it.
    ``distances()`` (node -> metres to the task's start) is only called when the task is not
    pinned; it may raise TaskError.
    """
    if task.pinned_robot is not None:
        robot = free.get(task.pinned_robot)
        if robot is not None and robot.out_of_service and task.kind not in MANUAL_KINDS:
            return None
        return robot
    dist = distances()
    ranked: list[tuple[bool, float, RobotInfo]] = []
    for robot in free.values():
        if robot.name in avoid or robot.out_of_service:
            continue
        if fits is not None and not fits(robot):
            continue
        cost = robot_cost(robot, dist.get(robot.node) if robot.node is not None else None)
        if extra_cost is not None:
            cost += extra_cost(robot)
        ranked.append((robot.name in rather_not, cost, robot))
    if not ranked:
        return None
    fallback = all(f for f, _, _ in ranked)
    pool = [(cost, r) for f, cost, r in ranked if f == fallback]
    cheapest = min(cost for cost, _ in pool)
    near = [(r.touring_s, cost, r.name, r) for cost, r in pool if cost <= cheapest + TURN_SLACK_S]
    return min(near, key=lambda x: x[:3])[3]


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


Errand = tuple[RobotInfo, str, dict[str, Any]]
"""An internal task for an idle robot: (robot, kind, params)."""


def idle_errands(
    idle: Iterable[RobotInfo],
    fleet: Iterable[RobotInfo],
    charging_at: Collection[str | None],
    site: Site,
    distances_to: Callable[[str], Distances],
    has_work: Callable[[RobotInfo], bool],
    barred: Callable[[RobotInfo, str], bool] | None = None,
    *,
    short: Callable[[RobotInfo], bool] | None = None,
) -> list[Errand]:
    """Where the ``idle`` robots (free as far as tasks go) go: charge if they must, else a
    free charging station, else the nearest wait point; nowhere if already at one, or if
    ``has_work`` (a queued task it can take). ``charging_at``: stations a charge task holds.
    Stations go to the emptiest robots first (those that must charge, then by battery), and a
    robot at a wait point below ``OPPORTUNISTIC_BELOW`` goes to a station that is free.
    ``short(robot)``: the queue holds work it may take but its battery would not last (above
    ``battery_low``, yet short of every such task): it charges as one that must, so that it
    takes the work after (else it stood idle at its wait point, work waiting, for ever).
    ``barred(robot, node)``: an errand of that robot to that node failed and nothing changed
    since (backend/tasks/blocked.py): it is not sent there."""
    free = [
        r
        for r in idle
        if r.current is None
        and r.online
        and not r.fault
        and not r.out_of_service
        and not has_work(r)
    ]
    if not free:
        return []
    is_short = short or (lambda _robot: False)
    must = {r.name for r in free if r.needs_charge or is_short(r)}
    candidates = sorted(free, key=lambda r: (r.name not in must, r.battery, r.name))
    at = {s.node: s.id for s in site.charging_stations}
    taken: set[str | None] = set(charging_at)
    taken |= {at[r.node] for r in fleet if r.node in at}
    wait_nodes = {w.node for w in site.wait_points}
    free_stations = [s for s in site.charging_stations if s.id not in taken]
    bar = barred or (lambda _robot, _node: False)
    errands: list[Errand] = []
    for robot in candidates:
        charge = robot.name in must
        if robot.node in at:
            if charge and robot.mode != "charging" and not bar(robot, robot.node):
                errands.append((robot, "charge", {"station": at[robot.node]}))
            continue
        open_stations = [s for s in free_stations if s.id not in taken and not bar(robot, s.node)]
        if robot.node in wait_nodes and not charge:
            if robot.battery >= OPPORTUNISTIC_BELOW or not open_stations:
                continue
        station = nearest(robot.node, open_stations, distances_to)
        if station is not None:
            taken.add(station.id)
            errands.append((robot, "charge", {"station": station.id}))
        elif not charge:
            waits = [w for w in site.wait_points if not bar(robot, w.node)]
            wait = nearest(robot.node, waits, distances_to)
            if wait is not None and wait.node != robot.node:
                errands.append((robot, "go_to", {"node": wait.node}))
    return errands
