"""A report's period: a day, a week or a custom range in the venue's time zone, whole hours,
read from query parameters with a clear error for anything else."""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

__all__ = ["MAX_DAYS", "BadPeriod", "Period", "parse_period"]

MAX_DAYS = 400
"""The longest range one report covers (a year and a bit)."""


class BadPeriod(ValueError):
    """The period asked for cannot be read or makes no sense (answered 422)."""


@dataclass(frozen=True)
class Period:
    start: float
    """Unix seconds, on the hour."""
    end: float
    """Unix seconds, on the hour, after ``start``."""
    tz: ZoneInfo
    bin_s: int
    """3600 (hour by hour) or 86400 (day by day)."""

    def label(self, at: float) -> str:
        """A bin's start in the venue's time, for charts and CSV."""
        local = dt.datetime.fromtimestamp(at, self.tz)
        return local.strftime("%Y-%m-%d" if self.bin_s == 86400 else "%Y-%m-%d %H:%M")

    def bin_of(self, hour: int) -> float:
        """The start of the bin that holds ``hour``: itself, or its local midnight."""
        if self.bin_s == 3600:
            return float(hour)
        local = dt.datetime.fromtimestamp(hour, self.tz)
        return local.replace(hour=0, minute=0, second=0).timestamp()

    def utc_days(self) -> bool:
        """Day by day on whole UTC days (the daily rollups hold the bins as they are)."""
        return (
            self.bin_s == 86400
            and self.start % 86400 == 0
            and self.end % 86400 == 0
            and all(
                dt.datetime.fromtimestamp(at, self.tz).utcoffset() == dt.timedelta(0)
                for at in range(int(self.start), int(self.end) + 1, 86400)
            )
        )

    def bins(self) -> list[float]:
        """Every bin's start, in order (empty bins too): each hour, or each local midnight
        (one date after the other: a day of 23 or 25 hours stays one bin)."""
        if self.bin_s == 3600:
            return [float(at) for at in range(int(self.start), int(self.end), 3600)]
        day = dt.datetime.fromtimestamp(self.start, self.tz).date()
        starts = [self.bin_of(int(self.start))]
        while True:
            day += dt.timedelta(days=1)
            at = dt.datetime(day.year, day.month, day.day, tzinfo=self.tz).timestamp()
            if at >= self.end:
                return starts
            starts.append(at)

    def as_dict(self) -> dict[str, object]:
        return {
            "start": dt.datetime.fromtimestamp(self.start, self.tz).isoformat(),
            "end": dt.datetime.fromtimestamp(self.end, self.tz).isoformat(),
            "tz": self.tz.key,
            "bin": "hour" if self.bin_s == 3600 else "day",
        }


def _zone(name: str) -> ZoneInfo:
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError):
        raise BadPeriod(
            f"unknown time zone {name!r} (an IANA name such as Europe/Madrid)"
        ) from None


def _date(text: str, what: str) -> dt.date:
    try:
        return dt.date.fromisoformat(text)
    except ValueError:
        raise BadPeriod(f"{what}={text!r} is not a date (YYYY-MM-DD)") from None


def _moment(text: str, what: str, tz: ZoneInfo) -> dt.datetime:
    try:
        moment = dt.datetime.fromisoformat(text)
    except ValueError:
        raise BadPeriod(f"{what}={text!r} is not a date and time (ISO 8601)") from None
    return moment if moment.tzinfo is not None else moment.replace(tzinfo=tz)


def _local_midnight(day: dt.date, tz: ZoneInfo) -> float:
    return dt.datetime(day.year, day.month, day.day, tzinfo=tz).timestamp()


def parse_period(
    *,
    day: str | None = None,
    week: str | None = None,
    start: str | None = None,
    end: str | None = None,
    tz: str = "UTC",
    bin: str | None = None,
) -> Period:
    """``day`` (a date), ``week`` (its first date: seven days) or ``start`` and ``end`` (ISO
    dates and times, ``end`` excluded, rounded out to whole hours) in time zone ``tz``;
    ``bin`` hour or day (default: hour up to two days, day beyond)."""
    zone = _zone(tz)
    given = [name for name, value in (("day", day), ("week", week), ("start", start)) if value]
    if len(given) != 1:
        raise BadPeriod(
            "give one period: day=YYYY-MM-DD, week=YYYY-MM-DD (its first day) or start= and end="
            + (f" (got {', '.join(given)})" if given else "")
        )
    if (start is None) != (end is None):
        raise BadPeriod("a custom range needs both start and end")
    if day:
        first = _local_midnight(_date(day, "day"), zone)
        last = _local_midnight(_date(day, "day") + dt.timedelta(days=1), zone)
    elif week:
        monday = _date(week, "week")
        first = _local_midnight(monday, zone)
        last = _local_midnight(monday + dt.timedelta(days=7), zone)
    else:
        assert start is not None and end is not None
        first = _moment(start, "start", zone).timestamp() // 3600 * 3600
        last = -(-_moment(end, "end", zone).timestamp() // 3600) * 3600
    if last <= first:
        raise BadPeriod("the period ends before it starts (end must be after start)")
    if last - first > MAX_DAYS * 86400:
        raise BadPeriod(f"the period is longer than {MAX_DAYS} days; ask for a shorter one")
    if bin not in (None, "hour", "day"):
        raise BadPeriod(f"bin={bin!r}: hour or day")
    bin_s = {"hour": 3600, "day": 86400}.get(
        bin or "", 3600 if last - first <= 2 * 86400 else 86400
    )
    return Period(start=first, end=last, tz=zone, bin_s=bin_s)
