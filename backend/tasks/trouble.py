"""A visitor's task cut off only by trouble waits for it (docs/server.md, "Building modes and
trouble"; issue 36).

A door that did not open or a lift that did not come closes itself for a while (trouble,
backend/closures). A visit whose only way it closes fails at its robot at once ("door D0 out
of order"); trouble is short-lived (it lifts when the device is seen working, its module is
back, or after the hold), so the visitor's task goes back to the queue and is given out again
once none of those closures is in force, instead of failing. In the fault soak, 12 of 106
visits failed so while each jam lasted seconds. After ``MAX_WAITS`` such waits it fails with
the reason (a door that stays broken). A closure by staff (a closed gallery) still fails at
once: the visitor is told why.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from backend.closures.model import Closure
from backend.closures.routing import RouteClosed, path_avoiding
from guidebot.site.graph import NoPath, SiteGraph, UnknownNode

__all__ = ["MAX_WAITS", "TroubleWaits"]

MAX_WAITS = 3
"""Waits for trouble a task may have before a failure so ends it."""


@dataclass(slots=True)
class _Wait:
    closures: frozenset[str]
    until: float
    """Unix seconds the last of those closures ends by itself."""
    count: int


class TroubleWaits:
    """The queued tasks waiting for trouble to lift."""

    def __init__(self, clock: Callable[[], float] = time.time) -> None:
        self.clock = clock
        self._waits: dict[str, _Wait] = {}

    def cut_by_trouble(
        self, graph: SiteGraph, start: str | None, goal: str, closed: Mapping[str, object]
    ) -> list[Closure] | None:
        """The trouble closures alone that cut ``goal`` off from ``start``, or None (open, or
        cut by staff too: then the failure stands)."""
        closures = {n: c for n, c in closed.items() if isinstance(c, Closure)}
        if not closures or start is None:
            return None
        try:
            path_avoiding(graph, start, goal, closures)
        except RouteClosed as exc:
            if exc.closures and all(c.source == "trouble" for c in exc.closures):
                return exc.closures
            return None
        except (NoPath, UnknownNode):
            return None
        return None

    def wait(self, task_id: str, closures: list[Closure]) -> bool:
        """``task_id`` waits for ``closures`` to lift; False when it has waited enough."""
        old = self._waits.get(task_id)
        count = (old.count if old is not None else 0) + 1
        if count > MAX_WAITS:
            return False
        ends = [c.end for c in closures if c.end is not None]
        until = max(ends) if ends else self.clock()
        self._waits[task_id] = _Wait(frozenset(c.id for c in closures), until, count)
        return True

    def held(self, task_id: str, closed: Mapping[str, object]) -> bool:
        """Still waiting: one of its closures is in force and not over."""
        wait = self._waits.get(task_id)
        if wait is None or self.clock() >= wait.until:
            return False
        return any(isinstance(c, Closure) and c.id in wait.closures for c in closed.values())

    def forget(self, task_id: str) -> None:
        self._waits.pop(task_id, None)
