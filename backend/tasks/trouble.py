"""A visitor's task cut off only by trouble waits for it (docs/server.md, "Building modes and
trouble"; docs/visitor.md; issue 36).

A door that did not open or a lift that did not come closes itself for a while (trouble,
backend/closures). A visit whose only way it closes fails at its robot at once ("door D0 out
of order"); trouble is short-lived (it lifts when the device is seen working, its module is
back, or after the hold), so the visitor's task goes back to the queue in its place and is
given out again once none of those closures is in force, instead of failing: in the fault soak
12 of 106 visits failed so while each jam lasted seconds. Its visitor is told why it waits
(``view``). A way still cut off after ``MAX_WAITS`` waits (a door that stays broken through
its holds) fails with the reason, and so does one a closure by staff cuts off (a closed
gallery): the visitor is told why.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from backend.closure import Closure
from backend.detours import RouteClosed
from backend.tasks.blocked import cut_off_by
from guidebot.site.graph import SiteGraph

__all__ = ["MAX_WAITS", "TroubleWaits"]

MAX_WAITS = 3
"""Waits for trouble a task may have before a failure so ends it."""


@dataclass(slots=True)
class _Wait:
    closures: frozenset[str]
    why: str
    """What cuts the way off, as RouteClosed says it ("door D0 out of order")."""
    count: int


class TroubleWaits:
    """The visitors' tasks waiting for trouble to lift, and how often each has waited."""

    def __init__(self) -> None:
        self._waits: dict[str, _Wait] = {}

    @staticmethod
    def cut_by_trouble(
        graph: SiteGraph, start: str | None, goal: str, closed: Mapping[str, object]
    ) -> RouteClosed | None:
        """What cuts ``goal`` off from ``start`` when it is trouble alone, or None (open, or
        cut by staff too: then the failure stands)."""
        cut = cut_off_by(graph, start, goal, closed) if start is not None else None
        if cut is not None and all(c.source == "trouble" for c in cut.closures):
            return cut
        return None

    def wait(self, task_id: str, cut: RouteClosed) -> bool:
        """``task_id`` waits for the closures of ``cut`` to lift; False when it has waited
        enough."""
        old = self._waits.get(task_id)
        count = (old.count if old is not None else 0) + 1
        if count > MAX_WAITS:
            return False
        self._waits[task_id] = _Wait(frozenset(c.id for c in cut.closures), cut.reason, count)
        return True

    def held(self, task_id: str, closed: Mapping[str, object]) -> bool:
        """Still waiting: one of the closures it waits for is in force."""
        wait = self._waits.get(task_id)
        if wait is None:
            return False
        return any(isinstance(c, Closure) and c.id in wait.closures for c in closed.values())

    def view(self, task_id: str, closed: Mapping[str, object]) -> dict[str, Any] | None:
        """What its visitor is told while it waits (``trouble`` of task_event and the REST
        status): {why, wait, waits}; None when it does not wait."""
        wait = self._waits.get(task_id)
        if wait is None or not self.held(task_id, closed):
            return None
        return {"why": wait.why, "wait": wait.count, "waits": MAX_WAITS}

    def waiting(self) -> list[str]:
        """The tasks that waited for trouble at least once and are not over."""
        return list(self._waits)

    def forget(self, task_id: str) -> None:
        self._waits.pop(task_id, None)
