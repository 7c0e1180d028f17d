"""Errands a robot could not do, not given again until something changes (docs/server.md,
"Charging").

An idle robot's errand (a charge task to a station, going to a wait point: choice.py,
``idle_errands``) that fails is otherwise made again at the next dispatch, at once: with a
door out of order between a robot that needs to charge and every charger, the fault soak made
and failed charge tasks hundreds of times a second for as long as the door was out (500 to
1 578 event-log rows a second for ~17 s, starving the other writers). So a failed errand bars
its target for that robot:

- when closures (trouble or staff, backend/closures) cut the target off from where the robot
  stands, until none of them is in force any more (the door works again, a closure ends);
  every other target they cut off too is barred with it (the next station is no better);
- otherwise (its route failed for a reason the server does not see), for a back-off of
  ``FIRST_BACKOFF_S`` doubling with each failure in a row up to ``MAX_BACKOFF_S``;
- never once the robot has moved to another node, or has charged (``clear``).

A bar says why in words made from typed fields only: the closures' own reasons, else the
errand's kind and the robot's ``trouble`` flag (task_ended's); never the robot's reason text,
which is words for people (an older robot's, another language's, any cause's).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from backend.closure import Closure
from backend.detours import RouteClosed, path_avoiding
from guidebot.site.graph import NoPath, SiteGraph, UnknownNode

__all__ = ["FIRST_BACKOFF_S", "MAX_BACKOFF_S", "Bar", "BlockedErrands", "cut_off_by", "describe"]

FIRST_BACKOFF_S = 5.0
"""Seconds a target whose failure no closure explains is barred after a first failure."""
MAX_BACKOFF_S = 60.0
"""The longest such back-off (failures in a row double it)."""


@dataclass(slots=True, frozen=True)
class Bar:
    """Why and until when a robot's errand to one target is not given again."""

    node: str
    """Where the robot stood when it failed (moved elsewhere: the bar no longer holds)."""
    closures: frozenset[str]
    """Ids of the closures that cut the target off (empty: a back-off in time)."""
    until: float
    """Clock time the back-off ends (closures: unused)."""
    why: str
    """What cuts the way off ("door D0 out of order"), else what failed (``describe``)."""


def cut_off_by(
    graph: SiteGraph, start: str, goal: str, closed: Mapping[str, object]
) -> RouteClosed | None:
    """What closures (any source) cut ``goal`` off from ``start``; None when the way is open
    or when there is no way at all."""
    closures = {n: c for n, c in closed.items() if isinstance(c, Closure)}
    if not closures:
        return None
    try:
        path_avoiding(graph, start, goal, closures)
    except RouteClosed as exc:
        return exc if exc.closures else None
    except (NoPath, UnknownNode):
        return None
    return None


ERRAND_WORDS = {"charge": "its charge at", "go_to": "its errand to"}
"""How a failed errand of each task kind is named."""


def describe(kind: str, goal: str, trouble: bool) -> str:
    """A failure no closure explains, from the typed fields: the errand's task ``kind`` and
    the robot's ``trouble`` flag (its way was cut off by trouble that has lifted since)."""
    what = f"{ERRAND_WORDS.get(kind, f'its {kind} to')} {goal}"
    if trouble:
        return f"trouble cut off {what} (none in force now)"
    return f"{what} failed (no closure cuts its way off)"


def _closed_bar(node: str, cut: RouteClosed, now: float) -> Bar:
    return Bar(node, frozenset(c.id for c in cut.closures), now, cut.reason)


class BlockedErrands:
    """Per robot, the targets (nodes) of its failed errands and what bars each."""

    def __init__(self) -> None:
        self._bars: dict[str, dict[str, Bar]] = {}
        self._failures: dict[str, int] = {}

    def failed(
        self,
        robot: str,
        node: str | None,
        goal: str,
        targets: Iterable[str],
        graph: SiteGraph,
        closed: Mapping[str, object],
        now: float,
        *,
        kind: str,
        trouble: bool = False,
    ) -> Bar | None:
        """``robot`` standing at ``node`` failed its errand (task ``kind``) to ``goal``: bar
        it, and every one of ``targets`` the same closures cut off. ``trouble``: the robot's
        flag (task_ended's: trouble alone cut its way off). Returns the bar of ``goal`` (None
        when the robot's place is unknown: nothing to compare a later place with)."""
        if node is None:
            return None
        bars = self._bars.setdefault(robot, {})
        cut = cut_off_by(graph, node, goal, closed)
        if cut is not None:
            bars[goal] = _closed_bar(node, cut, now)
            for other in targets:
                if other != goal and (also := cut_off_by(graph, node, other, closed)) is not None:
                    bars[other] = _closed_bar(node, also, now)
            return bars[goal]
        count = self._failures.get(robot, 0) + 1
        self._failures[robot] = count
        wait = min(MAX_BACKOFF_S, FIRST_BACKOFF_S * 2 ** (count - 1))
        bar = Bar(node, frozenset(), now + wait, describe(kind, goal, trouble))
        bars[goal] = bar
        return bar

    def barred(
        self, robot: str, node: str | None, goal: str, closed: Mapping[str, object], now: float
    ) -> Bar | None:
        """The bar that keeps ``robot`` at ``node`` from an errand to ``goal`` now, if any."""
        bar = self._bars.get(robot, {}).get(goal)
        if bar is None:
            return None
        if bar.node != node:
            return None
        if bar.closures:
            live = any(isinstance(c, Closure) and c.id in bar.closures for c in closed.values())
            return bar if live else None
        return bar if now < bar.until else None

    def clear(self, robot: str) -> None:
        """``robot`` did an errand (it charged, it reached its wait point): it starts afresh."""
        self._bars.pop(robot, None)
        self._failures.pop(robot, None)

    def any_bars(self, robot: str) -> bool:
        return bool(self._bars.get(robot))
