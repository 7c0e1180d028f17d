"""The fleet's safety invariants, checked on the event stream (hub messages or /api/events).

1. No robot reaches a door node while that door is closed.
2. No robot enters a cabin node unless the cabin is at that floor with its door open.
3. No two robots in one restricted area (by position, and by grants).

Fed with the building's broadcasts (door_opened / door_closed, elevator_in_position with
door_open), the robots' node_reached and the Traffic Manager's area_granted / area_released
(or the robots' release_area). Used by the integration tests and ``guidebot bench soak``;
it depends on nothing but the standard library, so any process can run it.

Order matters. The server's event log (GET /api/events: area_granted / area_released from the
Traffic Manager, the building's and robots' broadcasts) is in causal order. A monitor on the
hub itself sees a reaction published inside its cause's handler (area_granted, in the handler of
a release_area) *before* the cause: feed area_granted a moment later (``loop.call_soon``).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["InvariantChecker", "Violation"]


@dataclass(frozen=True)
class Violation:
    invariant: str
    """"door", "cabin" or "area"."""
    robot: str
    detail: str

    def __str__(self) -> str:
        return f"{self.invariant}: {self.robot}: {self.detail}"


@dataclass
class InvariantChecker:
    """Feed it events in the order the hub carried them; ``violations`` lists what broke."""

    door_at: Mapping[str, str]
    """node -> door"""
    cabin_at: Mapping[str, tuple[str, str]]
    """node -> (elevator, floor) of a cabin stop"""
    area_at: Mapping[str, str]
    """node -> restricted area"""
    violations: list[Violation] = field(default_factory=list)
    counts: dict[str, int] = field(
        default_factory=lambda: {"door": 0, "cabin": 0, "area": 0, "events": 0}
    )
    """How many times each invariant was checked (a run that checked nothing proves nothing)."""
    open_doors: set[str] = field(default_factory=set)
    cabins: dict[str, str] = field(default_factory=dict)
    """elevator -> floor where it stands with its door open"""
    position: dict[str, str] = field(default_factory=dict)
    holders: dict[str, str] = field(default_factory=dict)
    """area -> robot granted it"""

    @classmethod
    def from_site(cls, site: Any) -> InvariantChecker:
        """From a site document (guidebot.site.schema.Site or anything shaped like it)."""
        return cls(
            door_at={d.node: d.id for d in site.doors},
            cabin_at={s.node: (e.id, s.floor) for e in site.elevators for s in e.stops},
            area_at={n: a.id for a in site.areas for n in a.nodes},
        )

    def feed(self, kind: str, payload: Mapping[str, Any]) -> None:
        """One event: a message type (or event-log kind) and its payload."""
        self.counts["events"] += 1
        handler = getattr(self, f"_on_{kind}", None)
        if handler is not None:
            handler(payload)

    def feed_message(self, message: Any) -> None:
        """A hub message; replies addressed to one requester are not the building's state."""
        if message.type in ("door_opened", "door_closed", "elevator_in_position") and (
            message.destination is not None
        ):
            return
        self.feed(message.type, message.payload)

    def feed_events(self, events: Iterable[Mapping[str, Any]]) -> None:
        """Rows of GET /api/events (``kind`` and ``data``), oldest first."""
        for event in events:
            self.feed(str(event["kind"]), event.get("data") or {})

    def forget(self, robot: str) -> None:
        """The robot's position is no longer known (its process restarted elsewhere)."""
        self.position.pop(robot, None)

    def _fail(self, invariant: str, robot: str, detail: str) -> None:
        self.violations.append(Violation(invariant, robot, detail))

    def _on_door_opened(self, p: Mapping[str, Any]) -> None:
        self.open_doors.add(str(p.get("door")))

    def _on_door_closed(self, p: Mapping[str, Any]) -> None:
        self.open_doors.discard(str(p.get("door")))

    def _on_elevator_in_position(self, p: Mapping[str, Any]) -> None:
        elevator, floor = str(p.get("elevator")), str(p.get("floor"))
        if p.get("door_open", True):
            self.cabins[elevator] = floor
        elif self.cabins.get(elevator) == floor:
            del self.cabins[elevator]

    def _on_node_reached(self, p: Mapping[str, Any]) -> None:
        robot, node = str(p.get("robot")), str(p.get("node"))
        self.position[robot] = node
        door = self.door_at.get(node)
        if door is not None:
            self.counts["door"] += 1
            if door not in self.open_doors:
                self._fail("door", robot, f"reached {node} while door {door} was closed")
        cabin = self.cabin_at.get(node)
        if cabin is not None:
            self.counts["cabin"] += 1
            elevator, floor = cabin
            if self.cabins.get(elevator) != floor:
                where = self.cabins.get(elevator)
                state = f"open at {where}" if where else "closed or moving"
                self._fail("cabin", robot, f"entered {node} while {elevator} was {state}")
        area = self.area_at.get(node)
        if area is not None:
            self.counts["area"] += 1
            others = sorted(
                r for r, n in self.position.items() if r != robot and self.area_at.get(n) == area
            )
            if others:
                self._fail("area", robot, f"in area {area} at {node} with {', '.join(others)}")

    def _on_area_granted(self, p: Mapping[str, Any]) -> None:
        robot, area = str(p.get("robot")), str(p.get("area"))
        holder = self.holders.get(area)
        if holder is not None and holder != robot:
            self._fail("area", robot, f"granted area {area} still held by {holder}")
        self.holders[area] = robot

    def _on_server_started(self, p: Mapping[str, Any]) -> None:
        """A new server life starts with no locks: the robots declare theirs again (an
        ``area_granted`` with ``resync``); positions and the building are physical and stay."""
        self.holders.clear()

    def _on_release_area(self, p: Mapping[str, Any]) -> None:
        robot, area = str(p.get("robot")), str(p.get("area"))
        if self.holders.get(area) == robot:
            del self.holders[area]

    _on_area_released = _on_release_area
    _on_area_force_released = _on_release_area
