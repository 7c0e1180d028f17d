"""What an admin sets: the venue's SMTP server and the channels (an e-mail address or a webhook)
with their rules, as strict request bodies (unknown keys, wrong types and bad values: 422).

Secrets (the SMTP password, a webhook's secret) are write-only: ``view()`` never shows them,
only whether one is set."""

from __future__ import annotations

import datetime as dt
import ipaddress
import re
from typing import Annotated, Any, Literal
from urllib.parse import urlsplit
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from pydantic import AfterValidator, Field, model_validator

from backend.rest.models import RequestBody
from guidebot.payloads.alerts import AlertSeverity

__all__ = [
    "DAYS",
    "SEVERITIES",
    "Channel",
    "ChannelIn",
    "EmailChannel",
    "Smtp",
    "WebhookChannel",
    "Window",
]

SEVERITIES: tuple[AlertSeverity, ...] = ("warning", "error")
"""The alert layer's severities (guidebot/payloads/alerts.py)."""
Day = Literal["mon", "tue", "wed", "thu", "fri", "sat", "sun"]
DAYS: tuple[Day, ...] = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")
_LABEL = r"[A-Za-z0-9](?:[A-Za-z0-9-]*[A-Za-z0-9])?"
_ADDRESS = re.compile(rf"^[A-Za-z0-9.!#$%&'*+/=?^_`{{|}}~-]+@{_LABEL}(?:\.{_LABEL})+$")
_HOST = re.compile(r"^[A-Za-z0-9.:-]{1,253}$")  # a name or an address (IPv6 without brackets)


def _address(value: str) -> str:
    """An e-mail address as one mailbox: ``local@domain.tld``, nothing else (no display name,
    no list, no line break: it goes into a header)."""
    if len(value) > 254 or not _ADDRESS.fullmatch(value) or ".." in value:
        raise ValueError(f"{value!r} is not an e-mail address (name@domain.example)")
    return value


def _clock(value: str) -> str:
    if not re.fullmatch(r"([01]\d|2[0-3]):[0-5]\d|24:00", value):
        raise ValueError(f"{value!r} is not a time of day HH:MM (00:00 to 24:00)")
    return value


def _zone(value: str) -> str:
    try:
        ZoneInfo(value)
    except (ZoneInfoNotFoundError, ValueError):
        raise ValueError(f"{value!r} is not an IANA time zone (Europe/Paris, UTC...)") from None
    return value


def _minutes(clock: str) -> int:
    hours, minutes = clock.split(":")
    return int(hours) * 60 + int(minutes)


Address = Annotated[str, Field(min_length=3, max_length=254), AfterValidator(_address)]
Clock = Annotated[str, AfterValidator(_clock)]


class Window(RequestBody):
    """From ``start`` to ``end`` (local time, HH:MM); an end before the start runs past
    midnight (22:00 to 07:00)."""

    start: Clock
    end: Clock

    @model_validator(mode="after")
    def _not_empty(self) -> Window:
        if self.start == "24:00":
            raise ValueError("a window starts at 23:59 at the latest")
        if _minutes(self.start) == _minutes(self.end):
            raise ValueError(f"the window {self.start} to {self.end} is empty")
        return self

    def holds(self, minute: int) -> bool:
        """``minute`` (of the day) is inside."""
        start, end = _minutes(self.start), _minutes(self.end)
        if start < end:
            return start <= minute < end
        return minute >= start or minute < end


ALL_DAY = Window(start="00:00", end="24:00")


class _Rules(RequestBody):
    """When a channel is told: the fields both kinds share."""

    name: str = Field(min_length=1, max_length=64)
    """What the console shows (the person, the chat room)."""
    enabled: bool = True
    severities: list[AlertSeverity] = Field(default=list(SEVERITIES), min_length=1, max_length=2)
    days: list[Day] = Field(default=list(DAYS), min_length=1, max_length=7)
    hours: Window = ALL_DAY
    """The hours (on ``days``) it is told; outside them nothing is sent."""
    quiet: Window | None = None
    """Quiet hours: nothing is sent (every day)."""
    timezone: Annotated[str, Field(min_length=1, max_length=64), AfterValidator(_zone)] = "UTC"
    """The time zone of ``hours`` and ``quiet`` (the venue's)."""
    repeat_minutes: int | None = Field(default=None, ge=1, le=1440)
    """Sent again every so many minutes while the alert is open (not acknowledged, not
    resolved); null: once."""

    @model_validator(mode="after")
    def _unique(self) -> _Rules:
        for field in ("severities", "days"):
            values = getattr(self, field)
            if len(set(values)) != len(values):
                raise ValueError(f"{field} lists a value twice")
        return self

    def allows(self, severity: str, at: float) -> str | None:
        """Why this channel is not told of an alert of ``severity`` at ``at`` (None: it is)."""
        if not self.enabled:
            return "channel disabled"
        if severity not in self.severities:
            return f"severity {severity} not selected"
        local = dt.datetime.fromtimestamp(at, ZoneInfo(self.timezone))
        minute = local.hour * 60 + local.minute
        if DAYS[local.weekday()] not in self.days:
            return f"not on {DAYS[local.weekday()]}"
        if not self.hours.holds(minute):
            return f"outside the hours {self.hours.start} to {self.hours.end}"
        if self.quiet is not None and self.quiet.holds(minute):
            return f"quiet hours {self.quiet.start} to {self.quiet.end}"
        return None


class EmailChannel(_Rules):
    kind: Literal["email"]
    to: Address


def _webhook_url(value: str) -> str:
    """https://, or http:// to this machine only (a relay beside the server): an alert's text
    and its signature are not sent in clear over the venue's network."""
    parts = urlsplit(value)
    if parts.scheme not in ("https", "http") or not parts.hostname:
        raise ValueError(f"{value!r} is not an http(s) URL")
    if parts.username or parts.password:
        raise ValueError("the URL may not carry a user or password (the secret signs the body)")
    if parts.scheme == "http" and not _loopback(parts.hostname):
        raise ValueError(
            "a webhook URL must use https:// (http:// only to this machine: 127.0.0.1, ::1, "
            "localhost)"
        )
    return value


def _loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class WebhookChannel(_Rules):
    kind: Literal["webhook"]
    url: Annotated[str, Field(min_length=8, max_length=2000), AfterValidator(_webhook_url)]
    secret: str | None = Field(default=None, min_length=16, max_length=256)
    """The shared secret of the signature (write-only; omitted on a change: kept)."""


ChannelIn = Annotated[EmailChannel | WebhookChannel, Field(discriminator="kind")]


class Channel:
    """A stored channel: its rules and its id (``secret`` kept, never shown)."""

    def __init__(self, channel_id: str, rules: EmailChannel | WebhookChannel) -> None:
        self.id = channel_id
        self.rules = rules

    @property
    def kind(self) -> str:
        return self.rules.kind

    @property
    def target(self) -> str:
        """Where it goes, as the console shows it."""
        return self.rules.to if isinstance(self.rules, EmailChannel) else self.rules.url

    def view(self) -> dict[str, Any]:
        data = self.rules.model_dump(exclude={"secret"})
        if isinstance(self.rules, WebhookChannel):
            data["secret_set"] = bool(self.rules.secret)
        return {"id": self.id, **data}


class Smtp(RequestBody):
    """The venue's SMTP server (one for every e-mail channel)."""

    host: Annotated[str, Field(min_length=1, max_length=253, pattern=_HOST.pattern)]
    port: int = Field(default=587, ge=1, le=65535)
    security: Literal["starttls", "tls", "none"] = "starttls"
    """starttls: plain connection upgraded (port 587); tls: TLS from the start (465); none:
    no encryption (a relay on this machine or the venue's own LAN only)."""
    username: str | None = Field(default=None, min_length=1, max_length=256)
    password: str | None = Field(default=None, min_length=1, max_length=256)
    """Write-only; omitted on a change: the stored one is kept."""
    sender: Address
    """The From address."""
    timeout_s: float = Field(default=10.0, gt=0, le=60)

    def view(self) -> dict[str, Any]:
        return {**self.model_dump(exclude={"password"}), "password_set": bool(self.password)}
