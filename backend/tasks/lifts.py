"""Elevator-aware dispatch (docs/server.md, "Assignment"): a robot on another floor than a
task's start must ride a lift, and waits its turn behind every robot holding or waiting for a
lift's area. The Task Manager adds that wait to a robot's cost when it chooses one and to the
first leg when it foretells a wait (backend/tasks/choice.py, backend/tasks/eta.py).

The queue is read from the Traffic Manager's lock table (``lift_queue``), the lifts' ride times
from the site: one robot's turn is a ride both ways plus the doors (``turn_s``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Protocol

from guidebot.site.graph import SiteGraph
from guidebot.site.schema import Site

__all__ = ["DOORS_S", "LiftWait", "lift_queue"]

DOORS_S = 10.0
"""Doors opening, a robot driving in or out, doors closing: per turn, nominal seconds."""


class _LockView(Protocol):
    """What is read of one lock (backend.traffic.locks.LockView)."""

    @property
    def area(self) -> str: ...
    @property
    def holder(self) -> str | None: ...
    @property
    def waiting(self) -> list[str]: ...


def lift_queue(
    views: Callable[[], Iterable[_LockView]], graph: Callable[[], SiteGraph]
) -> Callable[[], int]:
    """Robots holding or waiting for a lift's area now (``views``: the Traffic Manager's
    ``lock_views``; ``graph``: its current site graph)."""

    def count() -> int:
        g = graph()
        lift_areas = {g.area_at[n] for n in g.elevator_at if n in g.area_at}
        robots: set[str] = set()
        for view in views():
            if view.area in lift_areas:
                robots.update(view.waiting)
                if view.holder is not None:
                    robots.add(view.holder)
        return len(robots)

    return count


class LiftWait:
    """Seconds a robot at one node waits for a lift before it can ride to another's floor."""

    def __init__(self, queue: Callable[[], int] | None = None) -> None:
        self.queue = queue
        """Robots in the lifts' queue now (None: no Traffic Manager, nobody waits)."""
        self._turn_s = 0.0

    def site_changed(self, site: Site) -> None:
        rides = [e.travel_time_s for e in site.elevators]
        self._turn_s = 2 * max(rides) + DOORS_S if rides else 0.0

    @property
    def turn_s(self) -> float:
        return self._turn_s

    def wait_s(self, graph: SiteGraph, start: str | None, goal: str, queued: int | None) -> float:
        """The wait for a lift between ``start`` and ``goal`` (0 on one floor, or unknown);
        ``queued``: the queue read once for a whole choice (``queue()``)."""
        if start is None or not queued:
            return 0.0
        here, there = graph.floor_of.get(start), graph.floor_of.get(goal)
        if here is None or there is None or here == there:
            return 0.0
        return queued * self._turn_s

    def queued(self) -> int:
        return self.queue() if self.queue is not None else 0
