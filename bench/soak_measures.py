"""What a soak tells about the visitors' tours (issue 36): the share of tours done, failures by
reason, how long a handover took, stops skipped, and each robot's touring time.

- ``done_share``: tasks done over tasks requested, leaving out those their visitor cancelled.
- ``handover_s``: from a robot's break to the next robot at the visitor's stop, the
  ``handover.arrived_after_s`` of each handed-over task (docs/protocol.md, "Handover").
- ``skipped_stops``: history rows ``point i/n skipped`` of the tours (stops a closure cut off).
- ``utilisation``: per robot, the seconds it held a visitor's task (from its assignment to the
  task's next change of robot or end, read from the event log, which survives server restarts)
  over the soak's length; ``touring_spread`` is (most - least) / mean of those seconds.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["Measures", "percentiles"]

SKIPPED = re.compile(r"^point \d+/\d+ skipped")


def percentiles(values: Iterable[float]) -> dict[str, float | None]:
    """p50 and p99 (nearest rank); None without values."""
    ordered = sorted(values)
    if not ordered:
        return {"p50": None, "p99": None}

    def rank(p: float) -> float:
        i = max(0, min(len(ordered) - 1, math.ceil(p * len(ordered)) - 1))
        return round(ordered[i], 1)

    return {"p50": rank(0.50), "p99": rank(0.99)}


@dataclass
class Measures:
    """Fed by the soak's referee (bench/soak_watch.py): task events from the event log, and
    the tasks' last listing."""

    holds: dict[str, tuple[str, float]] = field(default_factory=dict)
    """Task -> (robot, since) while a robot holds it."""
    touring_s: dict[str, float] = field(default_factory=dict)
    """Robot -> seconds it held visitors' tasks (closed intervals)."""
    spans: list[tuple[str, str, float]] = field(default_factory=list)
    """(task, robot, seconds) of every closed interval (the task's kind is known later)."""
    handovers: dict[str, float] = field(default_factory=dict)
    """Task -> seconds from the break to the new robot at the visitor."""
    skipped: dict[str, int] = field(default_factory=dict)

    def feed_event(self, kind: str, data: Mapping[str, Any], at: float | None) -> None:
        """One row of GET /api/events: ``task_<event>`` rows open and close the holds."""
        if not kind.startswith("task_") or at is None:
            return
        task = str(data.get("task_id") or "")
        if not task:
            return
        held = self.holds.pop(task, None)
        robot = data.get("robot")
        if held is not None and (kind != "task_started" or robot != held[0]):
            self.spans.append((task, held[0], max(0.0, at - held[1])))
        elif held is not None:
            self.holds[task] = held  # started by the robot that holds it: the hold goes on
            return
        state = data.get("state")
        if isinstance(robot, str) and state in ("assigned", "running"):
            self.holds[task] = (robot, at)

    def feed_task(self, task_id: str, listed: Mapping[str, Any]) -> None:
        """A task as GET /api/tasks lists it: its handover record."""
        handover = listed.get("handover")
        if isinstance(handover, dict) and isinstance(handover.get("arrived_after_s"), int | float):
            self.handovers[task_id] = float(handover["arrived_after_s"])

    def feed_history(self, task_id: str, rows: Iterable[Mapping[str, Any]]) -> None:
        self.skipped[task_id] = sum(1 for r in rows if SKIPPED.match(str(r.get("event", ""))))

    def result(
        self, visitor_tasks: Mapping[str, Any], robots: Iterable[str], seconds: float, now: float
    ) -> dict[str, Any]:
        """The soak's keys; ``visitor_tasks``: task id -> what was seen of it (state,
        cancelled_by); ``now``: when the soak ended (open holds close there)."""
        touring = dict.fromkeys(robots, 0.0)
        for task, robot, span in self.spans:
            if task in visitor_tasks and robot in touring:
                touring[robot] += span
        for task, (robot, since) in self.holds.items():
            if task in visitor_tasks and robot in touring:
                touring[robot] += max(0.0, now - since)
        seen = list(visitor_tasks.values())
        asked = [t for t in seen if getattr(t, "cancelled_by", "") != "requester"]
        done = sum(1 for t in asked if t.state == "done")
        mean = sum(touring.values()) / len(touring) if touring else 0.0
        spread = (max(touring.values()) - min(touring.values())) / mean if mean > 0 else None
        return {
            "done_share": round(done / len(asked), 3) if asked else None,
            "handover_s": percentiles(self.handovers.values()) | {"n": len(self.handovers)},
            "skipped_stops": sum(self.skipped.values()),
            "utilisation": {
                r: round(s / seconds, 3) if seconds > 0 else None for r, s in touring.items()
            },
            "touring_s": {r: round(s, 1) for r, s in touring.items()},
            "touring_spread": round(spread, 3) if spread is not None else None,
        }
