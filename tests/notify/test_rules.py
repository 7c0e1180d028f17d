"""A channel's rules on their own (backend/notify/model.py): windows past midnight, days and
hours in the channel's time zone, quiet hours, severities, a disabled channel."""

from __future__ import annotations

import datetime as dt
from typing import Any
from zoneinfo import ZoneInfo

from pydantic import TypeAdapter

from backend.notify.model import ChannelIn, EmailChannel, Window

CHANNEL: TypeAdapter[Any] = TypeAdapter(ChannelIn)


def at(text: str, zone: str = "UTC") -> float:
    return dt.datetime.fromisoformat(text).replace(tzinfo=ZoneInfo(zone)).timestamp()


def channel(**rules: Any) -> EmailChannel:
    parsed = CHANNEL.validate_python(
        {"kind": "email", "name": "Duty", "to": "d@m.example", **rules}
    )
    assert isinstance(parsed, EmailChannel)
    return parsed


def test_a_window_past_midnight() -> None:
    night = Window(start="22:00", end="07:00")
    assert [night.holds(m) for m in (22 * 60, 23 * 60 + 59, 0, 6 * 60 + 59)] == [True] * 4
    assert not night.holds(7 * 60) and not night.holds(12 * 60) and not night.holds(21 * 60 + 59)
    assert Window(start="00:00", end="24:00").holds(23 * 60 + 59)


def test_days_and_hours_are_the_channel_time_zone() -> None:
    # Sunday 23:30 in London is Monday 00:30 in Paris.
    sunday_night = at("2026-11-29T23:30:00", "Europe/London")
    paris = channel(days=["mon"], timezone="Europe/Paris")
    assert paris.allows("error", sunday_night) is None
    assert channel(days=["mon"]).allows("error", sunday_night) == "not on sun"
    office = channel(hours={"start": "09:00", "end": "17:00"}, timezone="Europe/Paris")
    assert office.allows("error", at("2026-11-30T09:00:00", "Europe/Paris")) is None
    assert office.allows("error", at("2026-11-30T17:00:00", "Europe/Paris")) == (
        "outside the hours 09:00 to 17:00"
    )


def test_quiet_hours_severities_and_a_disabled_channel() -> None:
    quiet = channel(quiet={"start": "22:00", "end": "07:00"})
    assert quiet.allows("error", at("2026-11-30T23:00:00")) == "quiet hours 22:00 to 07:00"
    assert quiet.allows("error", at("2026-11-30T07:00:00")) is None
    errors_only = channel(severities=["error"])
    assert (
        errors_only.allows("warning", at("2026-11-30T12:00:00")) == "severity warning not selected"
    )
    assert channel(enabled=False).allows("error", at("2026-11-30T12:00:00")) == "channel disabled"
