"""Staff alerts: the server's one store of conditions a person must look at (docs/console.md,
"Alerts"; messages in docs/messages.md, "Alerts").

One alert per cause, ``(kind, subject)``:
- raised again while it is active, it counts (``count``, ``last_seen``) and keeps its
  acknowledgement: acknowledging a cause that persists is not undone a second later;
- ``resolve`` closes it when its cause is gone (robot back, module back, door open...); raised
  after that, the same alert opens again (count + 1, to acknowledge again);
- an event alert (``lasting`` false: a task failed) has no cause to watch: acknowledging it
  resolves it.

Every change is published (``alert_raised``, ``alert_acked``, ``alert_resolved``) and written
to the event log under the same kinds; ``restore`` replays the log at start and resolves what
was still active, since nothing of the last server life is known to be current: causes that
persist are raised again by whoever sees them.
"""

from __future__ import annotations

import logging
import time
import uuid
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import asdict, dataclass, fields
from typing import Any

from guidebot.payloads.alerts import AlertPayload, AlertSeverity

__all__ = ["Alert", "AlertNotFound", "AlertStore"]

log = logging.getLogger("backend.alerts")

MAX_ALERTS = 2000
"""Resolved alerts beyond this are forgotten (oldest first); active ones are kept."""

LOGGED_KINDS = ("alert_raised", "alert_acked", "alert_resolved")
"""Event-log kinds of alert changes; each row holds the whole alert after the change."""

Publish = Callable[[str, AlertPayload], object]
Record = Callable[[str, str, dict[str, Any]], None]
"""``record(kind, source, data)``: a row of the event log (DbStore.record_event)."""


class AlertNotFound(KeyError):
    pass


@dataclass(slots=True)
class Alert:
    id: str
    kind: str
    subject: str
    message: str
    severity: AlertSeverity
    raised_at: float
    last_seen: float
    count: int = 1
    lasting: bool = True
    acked_by: str | None = None
    acked_at: float | None = None
    resolved_at: float | None = None
    resolution: str | None = None
    updated_at: float = 0.0

    @property
    def active(self) -> bool:
        """Its cause is (as far as the server knows) still there."""
        return self.resolved_at is None

    @property
    def open(self) -> bool:
        """Active and nobody has acknowledged it: the console's red bar."""
        return self.active and self.acked_at is None

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


_FIELDS = frozenset(f.name for f in fields(Alert))


class AlertStore:
    """Active and recent alerts, keyed by cause; every change published and logged."""

    def __init__(self, publish: Publish, record: Record | None = None) -> None:
        self.publish = publish
        self.record = record
        self.alerts: dict[str, Alert] = {}
        self._by_cause: dict[tuple[str, str], Alert] = {}

    # --- queries ------------------------------------------------------------------------
    def get(self, kind: str, subject: str) -> Alert | None:
        """The alert of this cause (active or resolved), if one is kept."""
        return self._by_cause.get((kind[:64], subject[:200]))

    def is_active(self, kind: str, subject: str) -> bool:
        alert = self.get(kind, subject)
        return alert is not None and alert.active

    def active(self) -> list[Alert]:
        return [a for a in self.alerts.values() if a.active]

    def listing(self, *, include_acked: bool = False) -> list[dict[str, Any]]:
        """Open alerts newest first; ``include_acked``: every kept one (acknowledged and
        resolved ones too)."""
        alerts = sorted(self.alerts.values(), key=lambda a: -a.last_seen)
        return [a.as_dict() for a in alerts if include_acked or a.open]

    # --- changes ------------------------------------------------------------------------
    def raise_(
        self,
        kind: str,
        subject: str,
        message: str,
        severity: AlertSeverity = "error",
        *,
        lasting: bool = True,
    ) -> Alert:
        """Raise the alert of this cause, or count it again if it is active (its
        acknowledgement stays); a resolved one opens again."""
        now = time.time()
        kind, subject, message = kind[:64], subject[:200], message[:500]  # the payload's bounds
        alert = self._by_cause.get((kind, subject))
        if alert is None:
            alert = Alert(uuid.uuid4().hex[:12], kind, subject, message, severity, now, now)
            alert.lasting = lasting
            self.alerts[alert.id] = alert
            self._by_cause[(kind, subject)] = alert
        elif alert.active:
            alert.count += 1
        else:  # the cause came back: a new occurrence, to acknowledge again
            alert.count += 1
            alert.acked_by = alert.acked_at = alert.resolved_at = alert.resolution = None
        alert.message, alert.severity, alert.last_seen, alert.updated_at = (
            message,
            severity,
            now,
            now,
        )
        log.warning("alert [%s %s] %s (x%d)", kind, subject, message, alert.count)
        self._changed("alert_raised", "alerts", alert)
        self._trim()
        return alert

    def resolve(self, kind: str, subject: str, why: str) -> Alert | None:
        """The cause is gone: the alert closes by itself (nothing if none is active)."""
        alert = self._by_cause.get((kind[:64], subject[:200]))
        if alert is None or not alert.active:
            return None
        self._resolve(alert, why, "alerts")
        return alert

    def resolve_where(self, kind: str, match: Callable[[str], bool], why: str) -> list[Alert]:
        """Resolve every active alert of ``kind`` whose subject ``match`` takes."""
        hits = [a for a in self.active() if a.kind == kind and match(a.subject)]
        for alert in hits:
            self._resolve(alert, why, "alerts")
        return hits

    def acknowledge(self, alert_id: str, by: str) -> Alert:
        """Someone has seen it (idempotent); an event alert is resolved by it."""
        alert = self.alerts.get(alert_id)
        if alert is None:
            raise AlertNotFound(alert_id)
        if alert.acked_at is None and alert.active:
            alert.acked_by, alert.acked_at = by, time.time()
            alert.updated_at = alert.acked_at
            self._changed("alert_acked", by, alert)
            if not alert.lasting:
                self._resolve(alert, f"acknowledged by {by}", by)
        return alert

    def acknowledge_all(self, by: str) -> list[Alert]:
        """Acknowledge every open alert; returns those acknowledged now."""
        opened = [a for a in self.alerts.values() if a.open]
        return [self.acknowledge(a.id, by) for a in opened]

    async def restore(
        self, events: Callable[..., Awaitable[list[dict[str, Any]]]], page: int = 1000
    ) -> list[Alert]:
        """Replay the log's alert rows (in id order); the alerts still active then are from
        the last server life and nothing says their causes are current: resolved (returned).
        Whoever sees a cause that persists raises it again."""
        after = 0
        while True:
            rows = await events(after_id=after, limit=page)
            self._replay(r for r in rows if r["kind"] in LOGGED_KINDS)
            if len(rows) < page:
                break
            after = rows[-1]["id"]
        stale = self.active()
        for alert in stale:
            self._resolve(alert, "server restarted: raised again if its cause is still there")
        self._trim()
        return stale

    # --- helpers ------------------------------------------------------------------------
    def _replay(self, rows: Iterable[dict[str, Any]]) -> None:
        for row in rows:
            data = row["data"]
            if not isinstance(data, dict) or not {"id", "kind", "subject"} <= data.keys():
                continue
            try:
                alert = Alert(**{k: v for k, v in data.items() if k in _FIELDS})
            except TypeError:
                continue  # a row of an older layout: not an alert this store can show
            old = self._by_cause.get((alert.kind, alert.subject))
            if old is not None and old.id != alert.id:
                self.alerts.pop(old.id, None)
            self.alerts[alert.id] = alert
            self._by_cause[(alert.kind, alert.subject)] = alert

    def _resolve(self, alert: Alert, why: str, source: str = "alerts") -> None:
        alert.resolved_at = alert.updated_at = time.time()
        alert.resolution = why[:500]
        log.info("alert resolved [%s %s] %s", alert.kind, alert.subject, why)
        self._changed("alert_resolved", source, alert)

    def _changed(self, kind: str, source: str, alert: Alert) -> None:
        data = alert.as_dict()
        if self.record is not None:
            self.record(kind, source, data)
        self.publish(kind, AlertPayload(**data))

    def _trim(self) -> None:
        resolved = sorted((a for a in self.alerts.values() if not a.active), key=_age)
        for alert in resolved[: max(0, len(self.alerts) - MAX_ALERTS)]:
            del self.alerts[alert.id]
            if self._by_cause.get((alert.kind, alert.subject)) is alert:
                del self._by_cause[(alert.kind, alert.subject)]


def _age(alert: Alert) -> float:
    return alert.last_seen
