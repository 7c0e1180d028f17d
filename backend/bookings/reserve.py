"""A robot reserved ahead for each booked occurrence (docs/server.md, "Bookings"): chosen
``RESERVE_AHEAD_S`` before the time among the robots in service, online and charged enough for
the way there and the tour; sent to the meeting point (a ``go_to`` task) in time to be there
``MARGIN_S`` early, then kept there; the booked tour is pinned to it at its time.

The Task Manager asks ``keeps(robot, task)`` before giving a robot a task (a reserved robot takes
no walk-up that would make it late) and ``parks(robot)`` before sending an idle robot to a
station (the reserved robot waits at its meeting point); the ETA estimator asks ``back_after``
so a walk-up's wait counts the reservation (backend/tasks/manager.py, backend/tasks/eta.py).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from backend.tasks.charging import can_finish
from backend.tasks.model import Task, TaskError
from backend.tasks.robots import RobotInfo

__all__ = ["MARGIN_S", "RESERVE_AHEAD_S", "Reservation", "Reservations"]

log = logging.getLogger(__name__)

RESERVE_AHEAD_S = 900.0
"""A robot is chosen this long before the booked time (15 minutes)."""
MARGIN_S = 60.0
"""It is sent to arrive this long before the booked time."""
UNKNOWN_TRAVEL_S = 300.0
"""The way to the meeting point when no path is known (a robot not placed yet)."""


@dataclass
class Reservation:
    booking: str
    at: float
    """The booked time (Unix seconds)."""
    robot: str
    node: str
    """The meeting point's node."""
    leave_at: float
    """When it must set off (Unix seconds)."""
    ends_at: float
    """When the booked tour is expected to end."""
    requester: str
    """The occurrence's requester (``booking:<id>@<unix time>``): its tasks are not walk-ups."""
    sent: str | None = None
    """The go_to task that takes it to the meeting point, once given."""

    def view(self) -> dict[str, Any]:
        return {"robot": self.robot, "leave_at": self.leave_at, "sent": self.sent}


class Reservations:
    """The reservations of the coming occurrences, kept in memory (rebuilt by the scheduler's
    next pass after a restart: a robot is chosen again)."""

    def __init__(
        self, tasks: Any, *, margin_s: float = MARGIN_S, clock: Callable[[], float] = time.time
    ) -> None:
        self.tasks = tasks
        """The Task Manager (robots, graph, estimator, request, cancel)."""
        self.margin_s = margin_s
        self.clock = clock
        self.by_robot: dict[str, Reservation] = {}
        self.by_key: dict[tuple[str, float], Reservation] = {}

    # -- hooks of the Task Manager and the ETA estimator ------------------------------------

    def keeps(self, robot: RobotInfo, task: Task) -> bool:
        """The robot is reserved and ``task`` (not the booking's) would make it late."""
        r = self.by_robot.get(robot.name)
        if r is None or task.requester.startswith(r.requester):
            return False
        now = self.clock()
        if now >= r.leave_at:
            return True
        took = self._task_s(task, robot.node)
        return now + took + self._travel_s(robot, r.node) > r.at - self.margin_s

    def parks(self, robot: RobotInfo) -> bool:
        """Sent to its meeting point: it waits there, not at a station."""
        r = self.by_robot.get(robot.name)
        return r is not None and r.sent is not None

    def back_after(self, name: str, free_in_s: float, task: Task) -> float | None:
        """For a walk-up's wait: None if robot ``name`` may take ``task`` when it is free in
        ``free_in_s`` seconds, else in how many seconds it is free after its booking."""
        r = self.by_robot.get(name)
        if r is None or task.requester.startswith(r.requester):
            return None
        now = self.clock()
        if now + free_in_s + self._task_s(task, None) <= r.leave_at:
            return None
        return max(free_in_s, r.ends_at - now)

    # -- planning ----------------------------------------------------------------------------

    def reserve(
        self, key: tuple[str, float], requester: str, node: str, duration_s: float
    ) -> Reservation | None:
        """Choose a robot for this occurrence (once); None when none fits now."""
        found = self.by_key.get(key)
        if found is not None:
            return found
        best: tuple[float, RobotInfo] | None = None
        for robot in self.tasks.robots.values():
            if robot.name in self.by_robot or not self._fits(robot):
                continue
            travel = self._travel_s(robot, node)
            if not can_finish(robot, travel + duration_s):
                continue
            busy = 0.0 if self._idle(robot) else 600.0  # rather a free robot
            cost = busy + travel
            if best is None or cost < best[0]:
                best = (cost, robot)
        if best is None:
            return None
        robot = best[1]
        at = key[1]
        r = Reservation(
            booking=key[0],
            at=at,
            robot=robot.name,
            node=node,
            leave_at=at - self.margin_s - self._travel_s(robot, node),
            ends_at=at + duration_s,
            requester=requester,
        )
        self.by_key[key] = self.by_robot[robot.name] = r
        log.info(
            "booking %s at %.0f: %s reserved, leaves at %.0f", key[0], at, robot.name, r.leave_at
        )
        self.tasks.dispatch()
        return r

    def send(self, now: float) -> None:
        """Reserved robots whose time to leave has come go to their meeting points."""
        for r in list(self.by_key.values()):
            if r.sent is not None or now < r.leave_at:
                continue
            robot = self.tasks.robots.get(r.robot)
            if robot is None or not self._fits(robot):
                self.drop(r, f"{r.robot} is no longer fit")
                continue
            current = self.tasks.tasks.get(robot.current) if robot.current else None
            if current is not None and not current.internal and not current.final:
                continue  # still on a task given before the reservation: it goes after
            try:
                task = self.tasks.request(
                    "go_to",
                    {"node": r.node},
                    priority=50,
                    requester=f"{r.requester}:meet",
                    robot=r.robot,
                )
            except TaskError as exc:
                log.warning("booking %s: cannot send %s to meet: %s", r.booking, r.robot, exc)
                continue
            r.sent = task.id

    def pinned(self, key: tuple[str, float]) -> str | None:
        """At its time: the reserved robot the booked task goes to (None: any), its way to
        the meeting point ended (cancelled if it has not arrived: the tour goes on from there)."""
        r = self.by_key.get(key)
        if r is None:
            return None
        self.release(key)
        if r.sent is not None:
            meet = self.tasks.tasks.get(r.sent)
            if meet is not None and not meet.final:
                try:
                    self.tasks.cancel(meet.id, reason="the booked tour starts", by="bookings")
                except TaskError:
                    pass
        robot = self.tasks.robots.get(r.robot)
        if robot is None or not self._fits(robot) or not self._idle(robot):
            return None  # lost, charging or still busy: the first robot free takes it
        return r.robot

    def release(self, key: tuple[str, float]) -> None:
        r = self.by_key.pop(key, None)
        if r is not None and self.by_robot.get(r.robot) is r:
            del self.by_robot[r.robot]

    def drop(self, r: Reservation, why: str) -> None:
        """Give a reservation up (its robot went out of service): the next pass chooses again."""
        log.info("booking %s: reservation of %s dropped: %s", r.booking, r.robot, why)
        self.release((r.booking, r.at))

    def forget_except(self, keys: set[tuple[str, float]]) -> None:
        """Drop reservations of occurrences no longer coming (cancelled, moved)."""
        for key in [k for k in self.by_key if k not in keys]:
            self.release(key)

    # -- helpers -----------------------------------------------------------------------------

    def _fits(self, robot: RobotInfo) -> bool:
        """In service, online, sound and not due to charge."""
        return (
            robot.online
            and not robot.out_of_service
            and not robot.fault
            and not robot.needs_charge
            and robot.battery > robot.config.battery_low
        )

    def _idle(self, robot: RobotInfo) -> bool:
        current = self.tasks.tasks.get(robot.current) if robot.current else None
        return current is None or current.internal or current.final

    def _travel_s(self, robot: RobotInfo, node: str) -> float:
        metres = self.tasks.graph.distances_to(node).get(robot.node) if robot.node else None
        if metres is None or not math.isfinite(metres):
            return UNKNOWN_TRAVEL_S
        return float(metres) / robot.config.max_speed_mps + self.tasks.lift_wait_s(robot.node, node)

    def _task_s(self, task: Task, start: str | None) -> float:
        try:
            took = self.tasks.estimator.task_s(task, start)
        except Exception:  # a target the site no longer has: assume the worst
            return math.inf
        return took if took is not None and math.isfinite(took) else UNKNOWN_TRAVEL_S
