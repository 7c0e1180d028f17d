"""A booking and its occurrences: what staff ask for (``BookingRequest``), what is kept
(``Booking``), and the dates a recurrence gives, in the venue's local time."""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterator
from typing import Annotated, Literal
from zoneinfo import ZoneInfo

from pydantic import BaseModel, ConfigDict, Field, StrictInt

from backend.rest.models import RequestBody

__all__ = [
    "DAYS",
    "MAX_GROUP",
    "Booking",
    "BookingError",
    "BookingRequest",
    "CancelRequest",
    "HistoryEntry",
    "MoveRequest",
    "Recurrence",
    "local_time",
    "occurrences",
]

DAYS = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")
"""Weekday names of a weekly recurrence, Monday first (``datetime.weekday()``)."""
MAX_GROUP = 500
"""The largest group one booking takes."""

Ref = Annotated[str, Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.-]+$")]
Day = Literal["mon", "tue", "wed", "thu", "fri", "sat", "sun"]
LocalTime = Annotated[
    str, Field(pattern=r"^\d{4}-\d{2}-\d{2}T\d{2}:\d{2}(:\d{2})?$", examples=["2026-12-01T14:00"])
]
"""A date and time in the venue's time zone (no offset): ``2026-12-01T14:00``."""
Date = Annotated[str, Field(pattern=r"^\d{4}-\d{2}-\d{2}$", examples=["2026-12-25"])]


class BookingError(ValueError):
    """Bad booking input or a rule it breaks (answered 422 with this text)."""


class Recurrence(RequestBody):
    """``once`` (default), ``daily``, or ``weekly`` on ``days`` (default: the first date's
    weekday); ``until`` the last date (inclusive, none: open-ended); ``except_dates`` skipped
    (closed days, a cancelled occurrence)."""

    every: Literal["once", "daily", "weekly"] = "once"
    days: list[Day] = Field(default_factory=list, max_length=7)
    until: Date | None = None
    except_dates: list[Date] = Field(default_factory=list, max_length=366)


class BookingRequest(RequestBody):
    """A new booking. ``tour`` or ``poi`` (one of them: a tour, or a single point's visit)."""

    tour: Ref | None = None
    poi: Ref | None = None
    start: LocalTime
    """The first (or only) occurrence, in the venue's local time."""
    lang: Annotated[str, Field(min_length=2, max_length=16)]
    group_size: StrictInt = Field(ge=1, le=MAX_GROUP)
    note: str = Field(default="", max_length=500)
    meeting_point: Ref | None = None
    """A point of interest; none: the tour's first stop (the visited point)."""
    public: bool = True
    """Shown on the visitor panel and the robots' screens as a "next tour" (a private school
    group: false)."""
    recurrence: Recurrence = Field(default_factory=Recurrence)


class MoveRequest(RequestBody):
    """Move a booking (a series: every coming occurrence) to a new start, and/or a new
    meeting point or group size."""

    start: LocalTime | None = None
    meeting_point: Ref | None = None
    group_size: StrictInt | None = Field(default=None, ge=1, le=MAX_GROUP)
    note: str | None = Field(default=None, max_length=500)


class CancelRequest(RequestBody):
    """Cancel the booking, or only one ``occurrence`` (a date) of a series."""

    occurrence: Date | None = None
    reason: str = Field(default="", max_length=200)


class HistoryEntry(BaseModel):
    at: float
    by: str
    action: str
    """created, moved, cancelled, occurrence_cancelled, started, missed, flagged."""
    detail: dict[str, object] = Field(default_factory=dict)


class Booking(BaseModel):
    """A kept booking (its ``data`` row)."""

    model_config = ConfigDict(extra="ignore")

    id: str
    kind: Literal["tour", "go_to_poi"]
    target: str
    """The tour's id (``tour``) or the point's (``go_to_poi``)."""
    start: str
    lang: str
    group_size: int
    note: str = ""
    meeting_point: str
    public: bool = True
    recurrence: Recurrence
    status: Literal["booked", "cancelled"] = "booked"
    created_by: str = ""
    created_at: float = 0.0

    @property
    def params(self) -> dict[str, object]:
        """The Task Manager's parameters of its task."""
        key = "tour" if self.kind == "tour" else "poi"
        return {key: self.target, "lang": self.lang}


YEARS = range(1970, 9999)
"""Dates a booking or a listing may name: a period's end plus some days must stay a date."""


def _in_range(day: dt.date, text: str, what: str) -> None:
    if day.year not in YEARS:
        raise BookingError(f"{what}={text!r} is out of range (years 1970 to 9998)")


def local_time(text: str, tz: ZoneInfo) -> dt.datetime:
    """``text`` (venue local, no offset) as an aware datetime; BookingError if it is no time."""
    try:
        moment = dt.datetime.fromisoformat(text)
    except ValueError:
        raise BookingError(f"start={text!r} is not a date and time (YYYY-MM-DDTHH:MM)") from None
    _in_range(moment.date(), text, "start")
    if moment.tzinfo is not None:
        return moment.astimezone(tz)
    return moment.replace(tzinfo=tz)


def local_date(text: str, what: str) -> dt.date:
    """``text`` as a date; BookingError naming ``what`` if it is none or out of range."""
    try:
        day = dt.date.fromisoformat(text)
    except ValueError:
        raise BookingError(f"{what}={text!r} is not a date (YYYY-MM-DD)") from None
    _in_range(day, text, what)
    return day


def check_recurrence(recurrence: Recurrence, first: dt.date) -> None:
    """BookingError for a recurrence that makes no sense from ``first``."""
    if recurrence.until is not None and local_date(recurrence.until, "until") < first:
        raise BookingError(f"until={recurrence.until} is before the first date {first}")
    if recurrence.days and recurrence.every != "weekly":
        raise BookingError("days are for a weekly recurrence (every=weekly)")
    for text in recurrence.except_dates:
        local_date(text, "except_dates")


def occurrences(booking: Booking, tz: ZoneInfo, start: float, end: float) -> Iterator[float]:
    """Unix times of the booking's occurrences in [start, end), in order (exceptions left out;
    a wall-clock time a DST change skips or repeats is taken as ``zoneinfo`` reads it)."""
    first = local_time(booking.start, tz)
    rec = booking.recurrence
    if rec.every == "once":
        at = first.timestamp()
        if start <= at < end:
            yield at
        return
    skip = {local_date(d, "except_dates") for d in rec.except_dates}
    until = local_date(rec.until, "until") if rec.until else None
    days = {DAYS.index(d) for d in rec.days} or {first.weekday()}
    day = max(first.date(), dt.datetime.fromtimestamp(start, tz).date() - dt.timedelta(days=1))
    last = dt.datetime.fromtimestamp(end, tz).date()
    while day <= last and (until is None or day <= until):
        if day not in skip and (rec.every == "daily" or day.weekday() in days):
            moment = dt.datetime.combine(day, first.timetz().replace(tzinfo=None), tzinfo=tz)
            stamp = moment.timestamp()
            if start <= stamp < end:
                yield stamp
        day += dt.timedelta(days=1)
