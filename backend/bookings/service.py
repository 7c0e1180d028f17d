"""BookingService: bookings checked against the site and the fleet, kept with their history
(docs/server.md, "Bookings"). No FastAPI here: the routes (``routes.py``) map ``BookingError``
to 422 and ``KeyError`` to 404; the scheduler (``schedule.py``) reads ``due``."""

from __future__ import annotations

import datetime as dt
import secrets
import time
from collections.abc import Callable
from typing import Any
from zoneinfo import ZoneInfo

from backend.bookings.model import (
    Booking,
    BookingError,
    BookingRequest,
    CancelRequest,
    HistoryEntry,
    MoveRequest,
    check_recurrence,
    local_time,
    occurrences,
)
from backend.bookings.store import BookingStore
from guidebot.site.i18n import site_languages
from guidebot.site.schema import Site

__all__ = ["OVERLAP_HORIZON_S", "BookingService"]

OVERLAP_HORIZON_S = 90 * 86400.0
"""How far ahead a recurring booking's occurrences are checked against the fleet (90 days)."""
DEFAULT_DURATION_S = 1800.0
"""A booking's length when the ETA estimator cannot tell (no path known): 30 minutes."""

Duration = Callable[[str, dict[str, Any]], float | None]
"""(task kind, its parameters) -> expected seconds (the Task Manager's ETA estimator)."""


class BookingService:
    """One per server (``app.state.bookings``): the bookings in memory, written through."""

    def __init__(
        self,
        store: BookingStore | None,
        site: Callable[[], Site],
        fleet: Callable[[], int],
        *,
        tz: ZoneInfo,
        duration: Duration | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.store = store
        self._site = site
        self.fleet = fleet
        """Robots in service now: no more simultaneous bookings than this."""
        self.tz = tz
        self._duration = duration
        self.clock = clock
        self.bookings: dict[str, Booking] = {}
        self._history: dict[str, list[HistoryEntry]] = {}
        self.on_change: list[Callable[[Booking], None]] = []
        self.flags: dict[tuple[str, float], str] = {}
        """(booking, occurrence) -> why it cannot be served (the scheduler's check ahead)."""
        self.reserved: Callable[[tuple[str, float]], str | None] = lambda key: None
        """(booking, occurrence) -> the robot reserved for it (backend/bookings/reserve.py)."""
        self.outcomes: dict[tuple[str, float], dict[str, Any]] = {}
        """(booking, occurrence) -> its start row (started with its task, or missed)."""

    async def restore(self) -> None:
        if self.store is not None:
            self.bookings = {b.id: b for b in await self.store.load()}

    # -- queries -----------------------------------------------------------------------------

    def get(self, booking_id: str) -> Booking:
        booking = self.bookings.get(booking_id)
        if booking is None:
            raise KeyError(booking_id)
        return booking

    def duration_s(self, booking: Booking) -> float:
        found = self._duration(booking.kind, booking.params) if self._duration else None
        return found if found is not None and found > 0 else DEFAULT_DURATION_S

    def between(
        self, start: float, end: float, *, cancelled: bool = False
    ) -> list[tuple[float, Booking]]:
        """Every occurrence in [start, end), in time order, with its booking."""
        found = [
            (at, b)
            for b in self.bookings.values()
            if cancelled or b.status == "booked"
            for at in occurrences(b, self.tz, start, end)
        ]
        return sorted(found, key=lambda pair: (pair[0], pair[1].id))

    def view(self, booking: Booking, at: float | None = None) -> dict[str, Any]:
        """A booking as the API shows it; with ``at``, one of its occurrences."""
        site = self._site()
        data = booking.model_dump(mode="json")
        data["name"] = _target_name(site, booking)
        poi = site.poi(booking.meeting_point)
        data["meeting_point_name"] = poi.name if poi else booking.meeting_point
        data["duration_s"] = round(self.duration_s(booking), 1)
        data["tz"] = self.tz.key
        if at is not None:
            data["at"] = at
            data["local"] = _local(at, self.tz)
            data["flag"] = self.flags.get((booking.id, at))
            data["robot"] = self.reserved((booking.id, at))
            outcome = self.outcomes.get((booking.id, at))
            data["outcome"] = outcome["outcome"] if outcome else None
            data["task_id"] = outcome.get("task_id") if outcome else None
            data["missed_reason"] = outcome.get("reason") or None if outcome else None
        return data

    def flags_view(self) -> list[dict[str, Any]]:
        """Occurrences that cannot be served as things stand, soonest first."""
        return [
            {"booking": b, "at": at, "local": _local(at, self.tz), "reason": why}
            for (b, at), why in sorted(self.flags.items(), key=lambda kv: kv[0][1])
        ]

    async def history(self, booking_id: str) -> list[dict[str, Any]]:
        self.get(booking_id)
        if self.store is None:
            return [e.model_dump() for e in self._history.get(booking_id, [])]
        return [e.model_dump() for e in await self.store.history(booking_id)]

    # -- changes -----------------------------------------------------------------------------

    async def create(self, body: BookingRequest, *, by: str) -> Booking:
        site = self._site()
        if (body.tour is None) == (body.poi is None):
            raise BookingError("give either tour (a tour's id) or poi (a single point's visit)")
        kind, target = ("tour", body.tour) if body.tour else ("go_to_poi", body.poi)
        assert target is not None
        first = self._check_target(site, kind, target)
        offered = site_languages(site)
        if body.lang not in offered:
            raise BookingError(f"language {body.lang!r} not offered (offered: {offered})")
        booking = Booking(
            id=secrets.token_hex(6),
            kind=kind,  # type: ignore[arg-type]
            target=target,
            start=body.start,
            lang=body.lang,
            group_size=body.group_size,
            note=body.note,
            meeting_point=self._check_point(site, body.meeting_point or first),
            public=body.public,
            recurrence=body.recurrence,
            created_by=by,
            created_at=self.clock(),
        )
        self._check_time(booking)
        self._check_fleet(booking)
        await self._save(booking, by, "created", {"start": booking.start})
        return booking

    async def move(self, booking_id: str, body: MoveRequest, *, by: str) -> Booking:
        old = self.get(booking_id)
        if old.status != "booked":
            raise BookingError(f"booking {booking_id} is {old.status}: it cannot be moved")
        self._refuse_taken(old, "moved")
        changes = body.model_dump(exclude_none=True)
        if not changes:
            raise BookingError("nothing to change: give start, meeting_point, group_size or note")
        if "meeting_point" in changes:
            self._check_point(self._site(), changes["meeting_point"])
        new = old.model_copy(update=changes)
        if "start" in changes:
            self._check_time(new)
        self._check_fleet(new)
        detail = {k: {"from": getattr(old, k), "to": v} for k, v in changes.items()}
        await self._save(new, by, "moved", detail)
        return new

    async def cancel(self, booking_id: str, body: CancelRequest, *, by: str) -> Booking:
        old = self.get(booking_id)
        if old.status != "booked":
            raise BookingError(f"booking {booking_id} is already {old.status}")
        self._refuse_taken(old, "cancelled", body.occurrence)
        if body.occurrence is None:
            new = old.model_copy(update={"status": "cancelled"})
            await self._save(new, by, "cancelled", {"reason": body.reason})
            return new
        day = body.occurrence
        if old.recurrence.every == "once" or day in old.recurrence.except_dates:
            raise BookingError(f"occurrence {day}: give a date of this series not yet cancelled")
        if not any(_local(at, self.tz)[:10] == day for at in self._dates_of(old, day)):
            raise BookingError(f"booking {booking_id} has no occurrence on {day}")
        rec = old.recurrence.model_copy(
            update={"except_dates": [*old.recurrence.except_dates, day]}
        )
        new = old.model_copy(update={"recurrence": rec})
        await self._save(new, by, "occurrence_cancelled", {"date": day, "reason": body.reason})
        return new

    async def note(self, booking: Booking, action: str, detail: dict[str, Any]) -> None:
        """A history entry by the scheduler (started, missed, flagged)."""
        entry = HistoryEntry(at=self.clock(), by="scheduler", action=action, detail=detail)
        if self.store is None:
            self._history.setdefault(booking.id, []).append(entry)
        else:
            await self.store.note(booking.id, entry)

    # -- rules -------------------------------------------------------------------------------

    def _check_target(self, site: Site, kind: str, target: str) -> str:
        """The target's first point (the default meeting point); BookingError if unknown."""
        if kind == "tour":
            tour = site.tour(target)
            if tour is None:
                known = [t.id for t in site.tours]
                raise BookingError(f"unknown tour {target!r} (the site's tours: {known})")
            return tour.points[0]
        if site.poi(target) is None:
            raise BookingError(f"unknown point of interest {target!r}")
        return target

    def _check_point(self, site: Site, poi: str) -> str:
        if site.poi(poi) is None:
            raise BookingError(f"unknown meeting point {poi!r} (a point of interest's id)")
        return poi

    def _check_time(self, booking: Booking) -> None:
        first = local_time(booking.start, self.tz)
        check_recurrence(booking.recurrence, first.date())
        now = self.clock()
        if booking.recurrence.every == "once" and first.timestamp() <= now:
            raise BookingError(
                f"start {booking.start} ({self.tz.key}) is in the past: "
                f"it is now {_local(now, self.tz)}"
            )
        if next(occurrences(booking, self.tz, now, now + OVERLAP_HORIZON_S * 4), None) is None:
            raise BookingError(f"the booking has no occurrence after now ({_local(now, self.tz)})")

    def _check_fleet(self, booking: Booking) -> None:
        """No more bookings at once than robots in service (over the next 90 days)."""
        robots = self.fleet()
        now = self.clock()
        mine = self.duration_s(booking)
        others = [
            (at, at + self.duration_s(b))
            for at, b in self.between(now - 86400, now + OVERLAP_HORIZON_S + 86400)
            if b.id != booking.id
        ]
        for at in occurrences(booking, self.tz, now, now + OVERLAP_HORIZON_S):
            busy = sum(1 for s, e in others if s < at + mine and at < e)
            if busy + 1 > robots:
                raise BookingError(
                    f"{busy + 1} bookings at once at {_local(at, self.tz)} but {robots} "
                    f"robot(s) in service: move it or cancel another"
                )

    def _refuse_taken(self, booking: Booking, change: str, day: str | None = None) -> None:
        """An occurrence the scheduler has started or recorded missed is history: a once
        booking's (the booking as a whole) or, with ``day``, a series' on that date. A series
        as a whole still changes its coming occurrences."""
        if day is None and booking.recurrence.every != "once":
            return
        if day is None:
            times = [local_time(booking.start, self.tz).timestamp()]
        else:
            times = [t for t in self._dates_of(booking, day) if _local(t, self.tz)[:10] == day]
        for at in times:
            taken = self.outcomes.get((booking.id, at))
            if taken is None:
                continue
            what = f"booking {booking.id} at {_local(at, self.tz).replace('T', ' ')}"
            if taken["outcome"] == "started":
                raise BookingError(
                    f"{what} has started (task {taken['task_id']}): it cannot be {change}; "
                    "cancel its task instead"
                )
            raise BookingError(f"{what} was missed: it cannot be {change}")

    def _dates_of(self, booking: Booking, day: str) -> list[float]:
        midnight = local_time(f"{day}T00:00", self.tz).timestamp()
        return list(occurrences(booking, self.tz, midnight - 7200, midnight + 93600))

    async def _save(self, booking: Booking, by: str, action: str, detail: dict[str, Any]) -> None:
        entry = HistoryEntry(at=self.clock(), by=by, action=action, detail=detail)
        if self.store is not None:
            await self.store.save(booking, entry)
        else:
            self._history.setdefault(booking.id, []).append(entry)
        self.bookings[booking.id] = booking
        for callback in self.on_change:
            callback(booking)


def _local(at: float, tz: ZoneInfo) -> str:
    return dt.datetime.fromtimestamp(at, tz).strftime("%Y-%m-%dT%H:%M")


def _target_name(site: Site, booking: Booking) -> str:
    if booking.kind == "tour":
        tour = site.tour(booking.target)
        return tour.name if tour else booking.target
    poi = site.poi(booking.target)
    return poi.name if poi else booking.target
