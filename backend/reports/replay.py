"""A past period of the event log to play back on the console: what the robots, doors, locks
and elevators did, and where they were when it started (docs/reports.md, "Replay")."""

from __future__ import annotations

from typing import Any

from sqlalchemy import or_, select

from backend.db.models import EventRow
from backend.reports.period import BadPeriod, Period

__all__ = ["MAX_REPLAY_S", "REPLAYED", "replay"]

MAX_REPLAY_S = 86400
"""The longest period one replay covers."""
LOOK_BACK_S = 86400
"""How far before the period its starting state is read from (each robot's last node, each
door, each lock and elevator)."""
MAX_EVENTS = 200_000
REPLAYED = (
    "node_reached",
    "door_opened",
    "door_closed",
    "elevator_in_position",
    "area_granted",
    "area_released",
    "area_force_released",
    "robot_connected",
    "robot_disconnected",
    "task_created",
    "task_started",
    "task_done",
    "task_failed",
    "task_cancelled",
    "alert_raised",
    "alert_resolved",
)


async def replay(sessionmaker: Any, period: Period) -> dict[str, Any]:
    """{"period", "start": the state when it starts, "events": [{at, kind, data}] in time order,
    "truncated"}; BadPeriod for a period longer than a day."""
    if period.end - period.start > MAX_REPLAY_S:
        raise BadPeriod("a replay covers at most 24 hours; ask for a shorter period")
    query = (
        select(EventRow.at, EventRow.kind, EventRow.data)
        .where(
            EventRow.at >= period.start - LOOK_BACK_S,
            EventRow.at < period.end,
            or_(EventRow.kind.in_(REPLAYED), EventRow.kind.like("task_point %")),
        )
        .order_by(EventRow.at, EventRow.id)
        .limit(MAX_EVENTS + 1)
    )
    async with sessionmaker() as session:
        rows = (await session.execute(query)).all()
    truncated = len(rows) > MAX_EVENTS
    start: dict[str, dict[str, Any]] = {"robots": {}, "doors": {}, "locks": {}, "elevators": {}}
    events = []
    for at, kind, data in rows[:MAX_EVENTS]:
        data = data if isinstance(data, dict) else {}
        if at >= period.start:
            events.append({"at": at, "kind": kind, "data": data})
        else:
            _apply(start, kind, data)
    return {"period": period.as_dict(), "start": start, "events": events, "truncated": truncated}


def _apply(state: dict[str, dict[str, Any]], kind: str, data: dict[str, Any]) -> None:
    """The state before the period: the same rules the console's player applies."""
    robot, area = data.get("robot"), data.get("area")
    if kind == "node_reached" and isinstance(robot, str):
        state["robots"][robot] = data.get("node")
    elif kind == "robot_disconnected" and isinstance(robot, str):
        state["robots"].pop(robot, None)
    elif kind in ("door_opened", "door_closed") and isinstance(data.get("door"), str):
        state["doors"][data["door"]] = kind == "door_opened"
    elif kind == "elevator_in_position" and isinstance(data.get("elevator"), str):
        state["elevators"][data["elevator"]] = data.get("floor")
    elif kind == "area_granted" and isinstance(area, str):
        state["locks"][area] = robot
    elif kind in ("area_released", "area_force_released") and isinstance(area, str):
        if state["locks"].get(area) == robot:
            del state["locks"][area]
