"""Who holds a VDA 5050 vehicle paused, kept in the event log so that it survives the master
control: a new leader (fail-over) or a restarted server reads it back (docs/vda5050.md,
"Pause"). The vehicle's state only says ``paused``; without its owner a new master could not
tell its own pause before a door (let go on once the door is answered) from staff's (kept).

Staff's pauses are the console's ``robot_paused`` / ``robot_resumed`` rows; the master's own,
``vda5050_pause`` rows {robot, paused, for, id} (for: ``door`` or ``elevator``)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

__all__ = ["PAUSE_EVENT", "STAFF_EVENTS", "PauseOwner", "owners_of", "read_owners"]

PAUSE_EVENT = "vda5050_pause"
"""The master's own pause (and its end) before a door or in a cabin."""
STAFF_EVENTS = ("robot_paused", "robot_resumed")
"""Staff's pause and let-go (backend/vda5050/routes.py)."""
READ_LAST = 1000
"""Rows of each kind read back: the newest per robot is all that counts."""


@dataclass(frozen=True)
class PauseOwner:
    """Who held one vehicle paused when the last master control stopped."""

    device: tuple[str, str] | None = None
    """The master's own pause: ("door", id) or ("elevator", id); None: none."""
    staff: bool = False
    """Staff paused it and did not let it go on since."""


class EventReader(Protocol):
    async def events(
        self, *, after_id: int = 0, limit: int = 100, kind: str | None = None, latest: bool = False
    ) -> list[dict[str, Any]]: ...


def owners_of(rows: Iterable[Mapping[str, Any]]) -> dict[str, PauseOwner]:
    """Robot -> who pauses it, from event rows ({id, kind, data}) of the kinds above: the
    newest row of each kind per robot."""
    device: dict[str, tuple[str, str] | None] = {}
    staff: dict[str, bool] = {}
    for row in sorted(rows, key=lambda r: int(r["id"])):
        data = row.get("data") or {}
        robot = data.get("robot")
        if not isinstance(robot, str):
            continue
        if row["kind"] == PAUSE_EVENT:
            held = bool(data.get("paused")) and isinstance(data.get("id"), str)
            device[robot] = (str(data.get("for") or "door"), str(data["id"])) if held else None
        elif row["kind"] in STAFF_EVENTS:
            staff[robot] = row["kind"] == "robot_paused"
    return {
        robot: PauseOwner(device.get(robot), staff.get(robot, False))
        for robot in device.keys() | staff.keys()
    }


async def read_owners(store: EventReader) -> dict[str, PauseOwner]:
    """Who pauses each vehicle, as the event log says."""
    rows: list[dict[str, Any]] = []
    for kind in (PAUSE_EVENT, *STAFF_EVENTS):
        rows += await store.events(kind=kind, latest=True, limit=READ_LAST)
    return owners_of(rows)
