"""What a fleet did, read from its event log: each tour's wait, and the day's lock waits,
elevator waits, robot time and busiest places (the Reports view's fold, summed over the run).

The planner's live run (``backend.planning.live``) and the check against a recording
(``guidebot bench plan-check``) measure with it, so both count a wait as the Reports view does:
from ``task_created`` to the first ``task_point 1/n arrived``."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from sqlalchemy import select

from backend.db import make_engine, make_sessionmaker
from backend.db.models import EventRow
from backend.reports.fold import Fold, Positions

__all__ = ["Event", "read_events", "tallies", "tour_ends", "tour_waits"]

Event = tuple[float, str, str, dict[str, Any]]
"""(at, kind, source, data) of one logged event."""


async def read_events(
    db_url: str, start: float | None = None, end: float | None = None
) -> list[Event]:
    """The log's events (``start`` <= at < ``end``), in id order."""
    engine = make_engine(db_url)
    try:
        query = select(EventRow.at, EventRow.kind, EventRow.source, EventRow.data)
        if start is not None:
            query = query.where(EventRow.at >= start)
        if end is not None:
            query = query.where(EventRow.at < end)
        async with make_sessionmaker(engine)() as session:
            rows = (await session.execute(query.order_by(EventRow.id))).all()
    finally:
        await engine.dispose()
    return [
        (at, kind, source, data if isinstance(data, dict) else {})
        for at, kind, source, data in rows
    ]


def tour_waits(events: Iterable[Event]) -> tuple[dict[str, float], dict[str, float], set[str]]:
    """Each tour's wait (task id -> seconds from its request to the robot at its first point),
    when each tour was requested (task id -> at), and the robots that connected."""
    created: dict[str, float] = {}
    waits: dict[str, float] = {}
    robots: set[str] = set()
    for at, kind, _, d in events:
        task = str(d.get("task_id"))
        if kind == "robot_connected" and isinstance(d.get("robot"), str):
            robots.add(d["robot"])
        elif kind == "task_created" and d.get("kind") == "tour":
            created[task] = at
        elif (
            kind.startswith("task_point 1/")
            and kind.endswith(" arrived")
            and task in created
            and task not in waits
        ):
            waits[task] = at - created[task]
    return waits, created, robots


TOUR_ENDS = ("task_done", "task_failed", "task_cancelled")


def tour_ends(events: Iterable[Event]) -> dict[str, str]:
    """How each task ended: task id -> its last ``task_done``, ``task_failed`` or
    ``task_cancelled`` (a task that has none has not ended)."""
    ends: dict[str, str] = {}
    for _, kind, _, d in events:
        if kind in TOUR_ENDS:
            ends[str(d.get("task_id"))] = kind
    return ends


def tallies(
    events: Iterable[Event], positions: Positions, end: float
) -> dict[str, dict[str, list[float]]]:
    """The Reports view's fold of ``events`` up to ``end``, summed over the hours:
    metric -> key -> [count, total] (``lock_wait`` by area, ``elevator_wait`` by elevator,
    ``robot_time`` by ``robot|state``, ``area_granted``, ``door_opened``, ``faults``...)."""
    fold = Fold(None, positions)
    fold.feed(events)
    fold.close(end)
    out: dict[str, dict[str, list[float]]] = {}
    for (metric, _, key), (n, total) in fold.tally.items():
        cell = out.setdefault(metric, {}).setdefault(key, [0, 0.0])
        cell[0] += n
        cell[1] += total
    return out
