"""Alerts: things staff must see at once and acknowledge (robot lost, lock holder offline,
door or elevator failure, Modbus module offline, CAN module lost, battery panic, task failed).

An alert is open until a staff member acknowledges it; who and when is recorded. Alerts are
kept as events of the event log (``alert_raised``, ``alert_acked``), so they survive a restart
without a table of their own: ``restore`` replays them.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Awaitable, Callable
from dataclasses import asdict, dataclass
from typing import Any, Literal, Protocol

from guidebot.payloads.console import ConsoleAlert

__all__ = ["Alert", "AlertBook", "AlertNotFound"]

Severity = Literal["warning", "error"]
MAX_ALERTS = 2000
"""Acknowledged alerts beyond this are forgotten (oldest first); open ones are kept."""


class AlertNotFound(KeyError):
    pass


@dataclass(slots=True)
class Alert:
    id: str
    kind: str
    subject: str
    message: str
    severity: Severity
    raised_at: float
    acked_by: str | None = None
    acked_at: float | None = None

    @property
    def open(self) -> bool:
        return self.acked_at is None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class EventSink(Protocol):
    def record_event(self, kind: str, source: str, data: dict[str, Any]) -> None: ...


class AlertBook:
    """Open and recent alerts; ``publish`` puts each change on the hub."""

    def __init__(self, sink: EventSink, publish: Callable[[str, ConsoleAlert], object]) -> None:
        self.sink = sink
        self.publish = publish
        self.alerts: dict[str, Alert] = {}

    async def restore(
        self, events: Callable[..., Awaitable[list[dict[str, Any]]]], page: int = 1000
    ) -> None:
        """Replay alert_raised/alert_acked from the event log (in id order)."""
        after = 0
        while True:
            rows = await events(after_id=after, limit=page)
            for row in rows:
                data = row["data"]
                if row["kind"] == "alert_raised":
                    alert = Alert(**{k: data[k] for k in Alert.__dataclass_fields__ if k in data})
                    self.alerts[alert.id] = alert
                elif row["kind"] == "alert_acked" and data.get("id") in self.alerts:
                    alert = self.alerts[data["id"]]
                    alert.acked_by, alert.acked_at = data.get("acked_by"), data.get("acked_at")
            if len(rows) < page:
                break
            after = rows[-1]["id"]
        self._trim()

    def open_alert(self, kind: str, subject: str) -> Alert | None:
        return next(
            (a for a in self.alerts.values() if a.open and a.kind == kind and a.subject == subject),
            None,
        )

    def raise_(self, kind: str, subject: str, message: str, severity: Severity = "error") -> Alert:
        """Raise an alert, unless the same one (kind and subject) is still open."""
        existing = self.open_alert(kind, subject)
        if existing is not None:
            return existing
        alert = Alert(uuid.uuid4().hex[:12], kind, subject, message, severity, time.time())
        self.alerts[alert.id] = alert
        self.sink.record_event("alert_raised", "console", alert.as_dict())
        self.publish("alert_raised", ConsoleAlert(**alert.as_dict()))
        self._trim()
        return alert

    def acknowledge(self, alert_id: str, by: str) -> Alert:
        alert = self.alerts.get(alert_id)
        if alert is None:
            raise AlertNotFound(alert_id)
        if alert.open:
            alert.acked_by, alert.acked_at = by, time.time()
            self.sink.record_event("alert_acked", by, alert.as_dict())
            self.publish("alert_acked", ConsoleAlert(**alert.as_dict()))
        return alert

    def listing(self, *, include_acked: bool = False) -> list[dict[str, Any]]:
        alerts = sorted(self.alerts.values(), key=lambda a: -a.raised_at)
        return [a.as_dict() for a in alerts if include_acked or a.open]

    def _trim(self) -> None:
        acked = sorted((a for a in self.alerts.values() if not a.open), key=lambda a: a.raised_at)
        for alert in acked[: max(0, len(self.alerts) - MAX_ALERTS)]:
            del self.alerts[alert.id]
