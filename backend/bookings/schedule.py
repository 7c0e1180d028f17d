"""The bookings' scheduler (leader only: it is a component, and components run on the process
that leads, backend/cluster.py): each occurrence becomes a task at its time, exactly once, and
one that cannot be served is flagged to staff before its time (docs/server.md, "Bookings").

Exactly once: the occurrence's row in ``booking_starts`` (primary key booking + time) is
written before its task is created; a second leader, or this one restarted, finds the row and
does not start it again. A row left without a task (the process died between the two writes)
gets its task on the next life unless the Task Manager already holds one with the occurrence's
requester (``booking:<id>@<unix time>``).
"""

from __future__ import annotations

import asyncio
import datetime as dt
import logging
import math
import time
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from backend.alerts import AlertStore
from backend.bookings.model import Booking
from backend.bookings.reserve import Reservations
from backend.bookings.service import BookingService
from backend.bookings.store import BookingStore
from backend.bookings.words import coming
from backend.closure import Closure, closed_nodes
from backend.db.session import log_failure
from backend.tasks.model import Task, TaskError
from backend.tasks.robots import RobotInfo
from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.bookings import NextTour, NextTours
from guidebot.service import Service
from guidebot.site.schema import Site

__all__ = ["BOOKING_PRIORITY", "LATE_CLEAR_S", "LATE_S", "BookingScheduler"]

log = logging.getLogger(__name__)

BOOKING_PRIORITY = 50
"""A booked occurrence's task priority: ahead of walk-ups (5) and panels (at most 5)."""
LATE_S = 600.0
"""An occurrence not started this long after its time (the server was down) is missed."""
RECONNECT_GRACE_S = 30.0
"""After a start (a restart, a new leader) robots reconnect: "no robot online" is not told to
staff before this many seconds."""
LATE_CLEAR_S = 20.0
"""A "cannot reach the meeting point in time" flag is resolved only once the robot can be
there this long before the time (an estimate that wobbles does not raise it again and again)."""
LATE_CONFIRM_S = 10.0
"""A reservation's lateness (or none to reserve) is told to staff once it has lasted this long."""
MISSED_LOOKBACK_S = 86400.0
"""At start: occurrences of the last day never started are told to staff as missed."""


class Fleet(Protocol):
    """What the scheduler needs of the Task Manager."""

    @property
    def robots(self) -> Mapping[str, RobotInfo]: ...
    @property
    def tasks(self) -> Mapping[str, Task]: ...
    @property
    def site(self) -> Site: ...

    def request(
        self,
        kind: str,
        params: dict[str, Any] | None = None,
        *,
        priority: int = 5,
        requester: str = "",
        robot: str | None = None,
        internal: bool = False,
    ) -> Task: ...


def requester_of(booking: Booking, at: float) -> str:
    return f"booking:{booking.id}@{int(at)}"


class BookingScheduler(Service):
    """Ticks every ``tick_s``; ``step(now)`` does one pass (tests drive it with their clock)."""

    def __init__(
        self,
        service: BookingService,
        store: BookingStore,
        fleet: Fleet,
        alerts: AlertStore | None,
        *,
        closures: Callable[[], list[Closure]] = list,
        alarm: Callable[[], str | None] = lambda: None,
        check_lead_s: float = 900.0,
        tick_s: float | None = 1.0,
        clock: Callable[[], float] = time.time,
        endpoint: BusEndpoint | None = None,
        reservations: Reservations | None = None,
    ) -> None:
        super().__init__()
        self.reservations = reservations
        """Robots reserved ahead (None: the booked task goes to whichever robot is free)."""
        self.endpoint = endpoint
        """Where ``next_tours`` goes (None: not told)."""
        self._told: list[NextTour] | None = None
        self.service = service
        self.store = store
        self.fleet = fleet
        self.alerts = alerts
        self.closures = closures
        self.alarm = alarm
        """Why no task may start now (a fire alarm), or None."""
        self.check_lead_s = check_lead_s
        self.tick_s = tick_s
        self.clock = clock
        self.done: dict[tuple[str, float], dict[str, Any]] = {}
        """Occurrences taken (this life or an earlier one) -> their start row."""
        self.flags: dict[tuple[str, float], str] = service.flags
        self._late_since: dict[tuple[str, float], float] = {}
        """Occurrences found late (reserve.py) -> since when (``LATE_CONFIRM_S``)."""
        self._lock = asyncio.Lock()
        self._started: float | None = None
        """time.monotonic() of the start (None: driven by a test, no grace)."""

    async def on_start(self) -> None:
        self._started = time.monotonic()
        await self.restore()
        if self.endpoint is not None:
            self.subscribe(self.endpoint, "robot_connected", self._on_robot_connected)
            self.service.on_change.append(lambda _: self.tell(self.clock()))
        if self.tick_s is not None:
            self.spawn(self._run(self.tick_s), name="booking-scheduler")

    async def restore(self) -> None:
        """The occurrences already taken; those of the last day never taken are missed."""
        now = self.clock()
        for row in await self.store.starts(now - MISSED_LOOKBACK_S - LATE_S):
            if row["task_id"] is None and row["outcome"] == "started":
                continue  # claimed, then the process died: ``_start`` finishes it
            self._taken((row["booking"], row["occurrence"]), row)
        for at, booking in self.service.between(now - MISSED_LOOKBACK_S, now - LATE_S):
            if (booking.id, at) not in self.done:
                await self._missed(booking, at, "the server was not running at its time")

    async def _run(self, tick_s: float) -> None:
        while True:
            try:
                await self.step(self.clock())
            except Exception as exc:  # one bad pass must not end the schedule
                log_failure(log, exc, "booking scheduler pass failed; trying again in %g s", tick_s)
            await asyncio.sleep(tick_s)

    async def step(self, now: float) -> None:
        self.tell(now)
        async with self._lock:
            if self.reservations is not None:
                self.reservations.refresh(now)
            kept: set[tuple[str, float]] = set()
            for at, booking in self.service.between(now - LATE_S, now + self.check_lead_s):
                key = (booking.id, at)
                if key in self.done:
                    continue
                if at <= now:
                    await self._start(booking, at)
                    continue
                reserving = self._reserve(booking, at, now)
                if reserving:
                    kept.add(key)
                await self._check(booking, at, now, reserving=reserving)
            self._late_since = {k: v for k, v in self._late_since.items() if k in kept}
            if self.reservations is not None:
                self.reservations.forget_except(kept)
                self.reservations.send(now)

    def _reserve(self, booking: Booking, at: float, now: float) -> bool:
        """Reserve a robot once the occurrence is within the lead, or before it when one must
        charge for it (reserve.py); True: it is."""
        if self.reservations is None:
            return False
        poi = self.fleet.site.poi(booking.meeting_point)
        key = (booking.id, at)
        if poi is None:
            return False
        duration = self.service.duration_s(booking)
        requester = requester_of(booking, at)
        if self.reservations.too_early(key, poi.node, now):
            # A robot may have to start charging for it already (reserve.py).
            return self.reservations.charge_ahead(key, requester, poi.node, duration) is not None
        self.reservations.reserve(key, requester, poi.node, duration)
        return True

    # -- telling visitors ---------------------------------------------------------------------

    def tell(self, now: float) -> None:
        """Broadcast ``next_tours`` when today's coming public tours changed."""
        tours = coming(self.service, now)
        if self.endpoint is None or tours == self._told:
            return
        self._told = tours
        self.endpoint.publish("next_tours", NextTours(tz=self.service.tz.key, tours=tours))

    def _on_robot_connected(self, message: Message) -> None:
        robot = message.payload.get("robot")
        if isinstance(robot, str) and self.endpoint is not None and self._told:
            news = NextTours(tz=self.service.tz.key, tours=self._told)
            self.endpoint.publish("next_tours", news, destination=robot)

    # -- starting ----------------------------------------------------------------------------

    async def _start(self, booking: Booking, at: float) -> None:
        key = (booking.id, at)
        requester = requester_of(booking, at)
        if not await self.store.claim(booking.id, at, "started"):
            rows = await self.store.starts(at)
            row = next((r for r in rows if (r["booking"], r["occurrence"]) == key), None)
            if row is not None and (row["task_id"] or row["outcome"] != "started"):
                self._taken(key, row)
                return
            task = next((t for t in self.fleet.tasks.values() if t.requester == requester), None)
            if task is not None:  # created, its row not updated: the process died between
                await self.store.started(booking.id, at, task.id)
                self._taken(key, {**(row or {}), "task_id": task.id, "outcome": "started"})
                return
        why = self.alarm()
        if why is not None:
            await self._missed(booking, at, why, claimed=True)
            return
        robot = self.reservations.pinned(key) if self.reservations is not None else None
        try:
            task = self.fleet.request(
                booking.kind,
                booking.params,
                priority=BOOKING_PRIORITY,
                requester=requester,
                robot=robot,
            )
        except TaskError as exc:
            await self._missed(booking, at, str(exc), claimed=True)
            return
        finally:
            if self.reservations is not None:
                self.reservations.release(key)  # kept from walk-ups until its task is made
        await self.store.started(booking.id, at, task.id)
        self._taken(key, {"task_id": task.id, "outcome": "started", "started_at": self.clock()})
        self._unflag(booking, at, f"started as task {task.id}")
        await self.service.note(booking, "started", {"at": at, "task_id": task.id})
        log.info("booking %s at %s started as task %s", booking.id, self._local(at), task.id)

    async def _missed(
        self, booking: Booking, at: float, why: str, *, claimed: bool = False
    ) -> None:
        if not claimed and not await self.store.claim(booking.id, at, "missed", why):
            return
        if claimed:
            await self.store.started(booking.id, at, None, outcome="missed", reason=why[:500])
        self._taken((booking.id, at), {"task_id": None, "outcome": "missed", "reason": why})
        self._unflag(booking, at, "missed")
        if self.alerts is not None:
            self.alerts.raise_(
                "booking_missed",
                self._subject(booking, at),
                f"{self._what(booking, at)} was not started: {why}",
                "error",
                lasting=False,
            )
        await self.service.note(booking, "missed", {"at": at, "reason": why})

    def _taken(self, key: tuple[str, float], row: dict[str, Any]) -> None:
        self.done[key] = row
        self.service.outcomes[key] = row

    # -- checking ahead ----------------------------------------------------------------------

    def trouble(self, booking: Booking, at: float) -> str | None:
        """Why this occurrence cannot be served as things stand (None: it can)."""
        if (why := self.alarm()) is not None:
            return f"alarm: {why}"
        robots = [r for r in self.fleet.robots.values() if not r.out_of_service]
        if not robots:
            return "no robot in service"
        if not any(r.online for r in robots):
            return None if self._reconnecting() else "no robot in service is online"
        site = self.fleet.site
        closed = closed_nodes(site, self.closures(), at)
        if closed:
            for node in self._nodes(site, booking):
                if node in closed:
                    closure = closed[node]
                    return f"{closure.what()} closed at its time" + (
                        f": {closure.reason}" if closure.reason else ""
                    )
        return None

    def late(self, booking: Booking, at: float) -> str | None:
        """Why the occurrence, within its reservation lead, will not have its robot at the
        meeting point by its time (None: it will): none could be reserved, the reserved one's
        battery will not last (no stand-in was found), or it cannot be there in time (its
        current task, then its way: reserve.py ``arrival``).
        Once told, it stays told until the robot can be there ``LATE_CLEAR_S`` early."""
        if self.reservations is None:
            return None
        key = (booking.id, at)
        found = self.reservations.arrival(key)
        poi = self.fleet.site.poi(booking.meeting_point)
        place = poi.name if poi is not None else booking.meeting_point
        by = dt.datetime.fromtimestamp(at, self.service.tz).strftime("%H:%M")
        if found is None:
            return (
                f"no robot can be reserved to be at {place} by {by}: every robot in service "
                "is reserved for another booking, due to charge or offline"
            )
        robot, when = found
        if self.reservations.short_of_battery(key):
            return (
                f"{robot}, the robot reserved, must charge first: its battery will not last "
                f"from now until the tour at {by} ends, and no other robot can be at {place} "
                "in time"
            )
        told = self.flags.get(key, "").startswith(f"{robot} cannot reach")
        if when <= at - (LATE_CLEAR_S if told else 0.0):
            return None
        current = self.fleet.robots.get(robot)
        if not math.isfinite(when):
            cause = "it is held up"
        elif current is not None and not self.reservations.idle(current):
            cause = "it is still on another task"
        else:
            cause = "its way there is too long"
        return f"{robot} cannot reach {place} by {by}: {cause}"

    def _reconnecting(self) -> bool:
        """Within the grace after a start: robots are still reconnecting."""
        return self._started is not None and time.monotonic() - self._started < RECONNECT_GRACE_S

    def _lasting(self, key: tuple[str, float], why: str | None, now: float) -> str | None:
        """``why`` once it has held ``LATE_CONFIRM_S`` (or the time is nearer than that), or
        it was told already: a robot held up at a door for a few seconds, an estimate that
        wobbles, is not told to staff."""
        if why is None:
            self._late_since.pop(key, None)
            return None
        since = self._late_since.setdefault(key, now)
        if key in self.flags or now - since >= LATE_CONFIRM_S or key[1] - now <= LATE_CONFIRM_S:
            return why
        return None

    async def _check(
        self, booking: Booking, at: float, now: float, *, reserving: bool = False
    ) -> None:
        why = self.trouble(booking, at)
        key = (booking.id, at)
        if why is None and reserving and not self._reconnecting():
            why = self._lasting(key, self.late(booking, at), now)
        if why is None:
            if key in self.flags:
                self._unflag(booking, at, "can be served again")
            return
        if self.flags.get(key) == why:
            return
        self.flags[key] = why
        if self.alerts is not None:
            self.alerts.raise_(
                "booking_at_risk",
                self._subject(booking, at),
                f"{self._what(booking, at)} cannot be served: {why}",
                "warning",
            )
        await self.service.note(booking, "flagged", {"at": at, "reason": why})

    def _unflag(self, booking: Booking, at: float, why: str) -> None:
        if self.flags.pop((booking.id, at), None) is not None and self.alerts is not None:
            self.alerts.resolve("booking_at_risk", self._subject(booking, at), why)

    # -- words -------------------------------------------------------------------------------

    def _nodes(self, site: Site, booking: Booking) -> list[str]:
        points = [booking.meeting_point]
        if booking.kind == "tour" and (tour := site.tour(booking.target)) is not None:
            points += tour.points
        elif booking.kind == "go_to_poi":
            points.append(booking.target)
        return [p.node for name in points if (p := site.poi(name)) is not None]

    def _local(self, at: float) -> str:
        return dt.datetime.fromtimestamp(at, self.service.tz).strftime("%Y-%m-%d %H:%M")

    def _subject(self, booking: Booking, at: float) -> str:
        return f"{booking.id}@{self._local(at)}"

    def _what(self, booking: Booking, at: float) -> str:
        view = self.service.view(booking)
        return (
            f"booking {booking.id} ({view['name']}, {booking.lang}, {booking.group_size} "
            f"people, meet at {view['meeting_point_name']}) at {self._local(at)}"
        )
