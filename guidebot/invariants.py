"""The fleet's safety invariants, checked on the event stream (hub messages or /api/events).

1. No robot reaches a door node while that door is closed (a door whose sensor cannot be read,
   ``door_closed`` with ``sensed`` false, is unknown: not checked until it is sensed again).
2. No robot enters a cabin node unless the cabin is at that floor with its door open. A robot
   that rode there (its last node another stop of that elevator) did not drive in: it arrived
   with the cabin, which must have stood at that floor with its door open at some moment of
   the ride (the robot reports its arrival once it has heard of it, and at time scale 10 the
   cabin's door may be closed again by then: the soak saw "entered lift1 while lift was closed
   or moving" for a robot that had ridden there).
3. No two robots in one restricted area (by position, and by grants).
4. While a fire alarm holds a zone (docs/emergency.md): no robot enters an escape route of the
   zone (a robot already in one may leave it), no elevator ride starts with a robot in the cabin
   when any stop of the elevator is in the zone, no door of the zone is opened but by a person
   (``door_opened_by_hand``). The alarm reaches a robot ``reach_s`` after it is declared (the
   chain input -> server -> robot takes that long; the bench's goal is 500 ms p99): the rules
   hold from then on, so a move or a door opening ordered just before the alarm is not counted.

Fed with the building's broadcasts (door_opened / door_closed, elevator_in_position with
door_open), the robots' node_reached and the Traffic Manager's area_granted / area_released
(or the robots' release_area), and the alarm's ``emergency_declared`` / ``emergency_resumed``
(event log) or ``emergency_changed`` (hub). Used by the integration tests, ``guidebot bench
soak`` and ``guidebot bench emergency``; it depends on nothing but the standard library, so
any process can run it.

Time, not arrival, decides. A robot whose link is down keeps its ``node_reached`` reports and
sends them when the link is back, seconds later: the soak saw a robot "enter a closed cabin"
that had been open when it drove in. So every event has a time (the event log's ``at``, or the
moment a live monitor saw it), ``node_reached`` carries the robot's own ``at`` (Unix seconds),
and each check is made against the building's and the other robots' state *at that time*:
doors, cabins and positions are kept as time lines, not as a last value.

Order still matters for grants. The server's event log (GET /api/events) is in causal order. A
monitor on the hub itself sees a reaction published inside its cause's handler (area_granted,
in the handler of a release_area) *before* the cause: feed area_granted a moment later
(``loop.call_soon``).
"""

from __future__ import annotations

import bisect
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

__all__ = ["ALARM_RULES", "InvariantChecker", "Violation"]

T = TypeVar("T")

ALARM_RULES = ("escape_route", "elevator_ride", "alarm_door")
"""The fire alarm's invariants (rule 4)."""
BY_HAND_S = 30.0
"""A door opening within this many seconds of a person's order (console) is that person's."""


@dataclass(frozen=True)
class Violation:
    invariant: str
    """"door", "cabin", "area", or an alarm rule: "escape_route", "elevator_ride",
    "alarm_door"."""
    robot: str
    detail: str
    at: float | None = None
    """When it happened (Unix seconds), if the events carried times."""

    def __str__(self) -> str:
        when = ""
        if self.at is not None and self.at > 1e9:  # a wall-clock time, not a sequence number
            when = time.strftime("%H:%M:%S", time.localtime(self.at)) + f".{self.at % 1:.3f}"[2:]
            when = f"{when} "
        return f"{when}{self.invariant}: {self.robot}: {self.detail}"


@dataclass
class TimeLine(Generic[T]):
    """A value that changes over time; reports may arrive out of time order."""

    initial: T
    times: list[float] = field(default_factory=list)
    values: list[T] = field(default_factory=list)

    def set(self, at: float, value: T) -> None:
        i = bisect.bisect_right(self.times, at)
        self.times.insert(i, at)
        self.values.insert(i, value)

    def at(self, when: float) -> T:
        i = bisect.bisect_right(self.times, when)
        return self.values[i - 1] if i else self.initial

    def last(self) -> T:
        return self.values[-1] if self.values else self.initial

    def changes(self, after: float, before: float) -> list[tuple[float, T]]:
        """The changes strictly after ``after`` and before ``before``."""
        lo = bisect.bisect_right(self.times, after)
        hi = bisect.bisect_left(self.times, before)
        return list(zip(self.times[lo:hi], self.values[lo:hi], strict=True))

    def since(self, when: float) -> float | None:
        """When the value ``when`` sees was set (None: the initial value)."""
        i = bisect.bisect_right(self.times, when)
        return self.times[i - 1] if i else None

    def next_change(self, after: float) -> float:
        i = bisect.bisect_right(self.times, after)
        return self.times[i] if i < len(self.times) else float("inf")


@dataclass
class InvariantChecker:
    """Feed it events with their times; ``violations`` lists what broke."""

    door_at: Mapping[str, str]
    """node -> door"""
    cabin_at: Mapping[str, tuple[str, str]]
    """node -> (elevator, floor) of a cabin stop"""
    area_at: Mapping[str, str]
    """node -> restricted area"""
    escape_at: Mapping[str, str] = field(default_factory=dict)
    """node -> escape route (a restricted area robots leave and avoid in an alarm)"""
    floor_of: Mapping[str, str] = field(default_factory=dict)
    """node -> floor (to know which nodes a floor's alarm holds)"""
    reach_s: float = 1.0
    """Seconds from an alarm's declaration to the moment its rules hold (see above)."""
    violations: list[Violation] = field(default_factory=list)
    counts: dict[str, int] = field(
        default_factory=lambda: {
            "door": 0,
            "cabin": 0,
            "area": 0,
            "escape_route": 0,
            "elevator_ride": 0,
            "alarm_door": 0,
            "events": 0,
        }
    )
    """How many times each invariant was checked (a run that checked nothing proves nothing)."""
    doors: dict[str, TimeLine[bool | None]] = field(default_factory=dict)
    """door -> open?"""
    cabins: dict[str, TimeLine[str | None]] = field(default_factory=dict)
    """elevator -> floor where it stands with its door open (None: closed or moving)"""
    positions: dict[str, TimeLine[str | None]] = field(default_factory=dict)
    """robot -> node (None: unknown)"""
    holders: dict[str, str] = field(default_factory=dict)
    """area -> robot granted it"""
    alarm: TimeLine[tuple[Mapping[str, Any], ...]] = field(default_factory=lambda: TimeLine(()))
    """The zones a fire alarm holds ({} the whole site, {floors} or {areas}); () none."""
    by_hand: dict[str, float] = field(default_factory=dict)
    """door -> the last time a person asked for it to open (console)."""
    _now: float = 0.0
    """The latest event time seen; events fed without a time come just after it."""
    _area_claims: list[tuple[float, str, str, tuple[str, ...], Violation]] = field(
        default_factory=list
    )
    """Area violations as (time, area, robot, the robots it was with, the violation): a
    report that comes late may show that those had left by then (``_recheck_area``)."""

    @classmethod
    def from_site(cls, site: Any) -> InvariantChecker:
        """From a site document (guidebot.site.schema.Site or anything shaped like it)."""
        emergency = getattr(site, "emergency", None)
        routes = set(emergency.escape_routes) if emergency is not None else set()
        return cls(
            door_at={d.node: d.id for d in site.doors},
            cabin_at={s.node: (e.id, s.floor) for e in site.elevators for s in e.stops},
            area_at={n: a.id for a in site.areas for n in a.nodes},
            escape_at={n: a.id for a in site.areas if a.id in routes for n in a.nodes},
            floor_of={n.id: n.floor for n in site.nodes},
        )

    @property
    def position(self) -> dict[str, str]:
        """Each robot's last known node."""
        return {r: n for r, line in self.positions.items() if (n := line.last()) is not None}

    def feed(self, kind: str, payload: Mapping[str, Any], at: float | None = None) -> None:
        """One event: a message type (or event-log kind), its payload and when it happened."""
        self.counts["events"] += 1
        if at is None:
            at = self._now + 1e-6
        self._now = max(self._now, at)
        handler = getattr(self, f"_on_{kind}", None)
        if handler is not None:
            handler(payload, at)

    def feed_message(self, message: Any) -> None:
        """A hub message as it passes; replies addressed to one requester are not the
        building's state."""
        if message.type in ("door_opened", "door_closed", "elevator_in_position") and (
            message.destination is not None
        ):
            return
        self.feed(message.type, message.payload, time.time())

    def feed_events(self, events: Iterable[Mapping[str, Any]]) -> None:
        """Rows of GET /api/events (``kind``, ``data`` and ``at``), oldest first."""
        for event in events:
            at = event.get("at")
            self.feed(
                str(event["kind"]),
                event.get("data") or {},
                float(at) if isinstance(at, int | float) else None,
            )

    def forget(self, robot: str, at: float | None = None) -> None:
        """The robot's position is no longer known from ``at`` on (its process restarted)."""
        self._line(self.positions, robot, None).set(self._now if at is None else at, None)

    @staticmethod
    def _line(lines: dict[str, TimeLine[Any]], key: str, initial: Any) -> TimeLine[Any]:
        line = lines.get(key)
        if line is None:
            line = lines[key] = TimeLine(initial)
        return line

    def _fail(self, invariant: str, robot: str, detail: str, at: float) -> None:
        self.violations.append(Violation(invariant, robot, detail, at))

    def _on_door_opened(self, p: Mapping[str, Any], at: float) -> None:
        self._line(self.doors, str(p.get("door")), False).set(at, True)
        self._alarm_door(str(p.get("door")), at)

    def _on_door_closed(self, p: Mapping[str, Any], at: float) -> None:
        known = p.get("sensed", True) is not False
        self._line(self.doors, str(p.get("door")), False).set(at, False if known else None)

    def _on_elevator_in_position(self, p: Mapping[str, Any], at: float) -> None:
        elevator, floor = str(p.get("elevator")), str(p.get("floor"))
        line = self._line(self.cabins, elevator, None)
        if p.get("door_open", True):
            line.set(at, floor)
        elif line.at(at) == floor:
            line.set(at, None)

    def _on_node_reached(self, p: Mapping[str, Any], at: float) -> None:
        robot, node = str(p.get("robot")), str(p.get("node"))
        reached = p.get("at")
        if isinstance(reached, int | float) and reached <= at:
            at = float(reached)  # the robot's time: it may report late, never early
        line = self._line(self.positions, robot, None)
        before, before_at = line.at(at), line.since(at)
        line.set(at, node)
        self._check_alarm_move(robot, node, before, before_at, at)
        door = self.door_at.get(node)
        if door is not None:
            self.counts["door"] += 1
            if self._line(self.doors, door, False).at(at) is False:
                self._fail("door", robot, f"reached {node} while door {door} was closed", at)
        cabin = self.cabin_at.get(node)
        if cabin is not None:
            self.counts["cabin"] += 1
            elevator, floor = cabin
            cabin_line = self._line(self.cabins, elevator, None)
            where = cabin_line.at(at)
            came_from = self.cabin_at.get(before or "")
            if (
                where != floor
                and before_at is not None
                and came_from is not None
                and came_from[0] == elevator
                and came_from[1] != floor
                and any(w == floor for _, w in cabin_line.changes(before_at, at))
            ):
                where = floor  # rode there: the cabin stood open at this floor on the way
            if where != floor:
                state = f"open at {where}" if where else "closed or moving"
                self._fail("cabin", robot, f"entered {node} while {elevator} was {state}", at)
        area = self.area_at.get(node)
        if area is not None:
            self.counts["area"] += 1
            self._check_area(robot, node, area, at)
        if self._area_claims:
            self._recheck_area(robot, at)

    def _area_of(self, robot: str, at: float) -> str | None:
        node = self.positions[robot].at(at)
        return self.area_at.get(node) if node is not None else None

    def _check_area(self, robot: str, node: str, area: str, at: float) -> None:
        """``robot`` is in ``area`` from ``at`` until its next move: nobody else may be in it
        at ``at``, nor enter it in that time (a report that came in late finds those)."""
        until = self.positions[robot].next_change(at)
        others = []
        for other, line in self.positions.items():
            if other == robot:
                continue
            if self._area_of(other, at) == area:
                others.append(other)
                continue
            for when, there in line.changes(at, until):
                if there is not None and self.area_at.get(there) == area:
                    self._area_fail(other, area, (robot,), f"at {there}", when)
                    break
        if others:
            self._area_fail(robot, area, tuple(others), f"at {node}", at)

    def _area_fail(
        self, robot: str, area: str, others: tuple[str, ...], where: str, at: float
    ) -> None:
        self._fail("area", robot, f"in area {area} {where} with {', '.join(others)}", at)
        self._area_claims.append((at, area, robot, others, self.violations[-1]))

    def _recheck_area(self, robot: str, since: float) -> None:
        """``robot``'s report of ``since`` came after area violations of later times that
        name it: those its new place disproves go (a robot's node_reached sent again after a
        server restart showed it had left the corridor before another entered)."""
        kept = []
        for claim in self._area_claims:
            at, area, subject, others, violation = claim
            if at >= since and robot in (subject, *others):
                together = self._area_of(subject, at) == area and any(
                    self._area_of(o, at) == area for o in others
                )
                if not together:
                    self.violations.remove(violation)
                    continue
            kept.append(claim)
        self._area_claims = kept

    def _on_area_granted(self, p: Mapping[str, Any], at: float) -> None:
        robot, area = str(p.get("robot")), str(p.get("area"))
        holder = self.holders.get(area)
        if holder is not None and holder != robot:
            self._fail("area", robot, f"granted area {area} still held by {holder}", at)
        self.holders[area] = robot

    def _on_server_started(self, p: Mapping[str, Any], at: float) -> None:
        """A new server life starts with the locks of the last one logged again (an
        ``area_granted`` with ``restored``) and the robots' own word (``resync``); positions
        and the building are physical and stay."""
        self.holders.clear()

    def _on_release_area(self, p: Mapping[str, Any], at: float) -> None:
        robot, area = str(p.get("robot")), str(p.get("area"))
        if self.holders.get(area) == robot:
            del self.holders[area]

    _on_area_released = _on_release_area
    _on_area_force_released = _on_release_area

    # -- the fire alarm's rules ------------------------------------------------------------

    def _zone_holds(self, zone: Mapping[str, Any], node: str) -> bool:
        floors, areas = zone.get("floors") or [], zone.get("areas") or []
        if floors:
            return self.floor_of.get(node) in floors
        if areas:
            return self.area_at.get(node) in areas
        return True

    def held(self, node: str, at: float) -> bool:
        """An alarm holds ``node`` at ``at`` and has held it for ``reach_s`` already."""
        return all(
            any(self._zone_holds(z, node) for z in self.alarm.at(t))
            for t in (at, at - self.reach_s)
        )

    def _check_alarm_move(
        self, robot: str, node: str, before: str | None, before_at: float | None, at: float
    ) -> None:
        route = self.escape_at.get(node)
        if route is not None and before is not None and self.escape_at.get(before) != route:
            self.counts["escape_route"] += 1
            if self.held(node, at):
                self._fail("escape_route", robot, f"entered escape route {route} at {node}", at)
        cabin, came_from = self.cabin_at.get(node), self.cabin_at.get(before or "")
        if cabin is None or came_from is None or before_at is None:
            return
        (elevator, floor), (was_elevator, was_floor) = cabin, came_from
        if elevator != was_elevator or floor == was_floor:
            return
        self.counts["elevator_ride"] += 1
        # The ride started when the cabin, with the robot in it, left the robot's floor.
        cabin_line = self._line(self.cabins, elevator, None)
        start = next(
            (t for t, where in cabin_line.changes(before_at, at) if where != was_floor), at
        )
        stops = [n for n, (e, _) in self.cabin_at.items() if e == elevator]
        if any(self.held(stop, start) for stop in stops):
            self._fail(
                "elevator_ride",
                robot,
                f"rode {elevator} from {was_floor} to {floor} during the fire alarm",
                start,
            )

    def _alarm_door(self, door: str, at: float) -> None:
        node = next((n for n, d in self.door_at.items() if d == door), None)
        if node is None:
            return
        self.counts["alarm_door"] += 1
        if not self.held(node, at):
            return
        asked = self.by_hand.get(door)
        if asked is not None and asked <= at <= asked + BY_HAND_S:
            return  # a person opened it (the console), not the fleet for a robot
        self._fail("alarm_door", "-", f"door {door} opened during the fire alarm", at)

    def _on_door_opened_by_hand(self, p: Mapping[str, Any], at: float) -> None:
        self.by_hand[str(p.get("door"))] = at

    def _on_emergency_declared(self, p: Mapping[str, Any], at: float) -> None:
        zones = p.get("zones")
        self.alarm.set(at, tuple(zones) if isinstance(zones, list) and zones else ({},))

    def _on_emergency_resumed(self, p: Mapping[str, Any], at: float) -> None:
        self.alarm.set(at, ())

    def _on_emergency_changed(self, p: Mapping[str, Any], at: float) -> None:
        """The hub's broadcast: ``state`` normal, alarm or input_clear (still held)."""
        if p.get("state") == "normal":
            if self.alarm.at(at):
                self.alarm.set(at, ())
        else:
            self._on_emergency_declared(p, at)
