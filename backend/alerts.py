"""Staff alerts: conditions a person must look at, as ``staff_alert`` messages on the hub, a
warning in the log and a row in the event log (docs/messages.md, "Alerts").

An alert is raised once under a stable ``alert_id`` and cleared under the same id, so a console
that keeps the active ones by id shows each condition once, however often it is re-checked.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any, Literal

from guidebot.bus import BusEndpoint
from guidebot.payloads.alerts import AlertKind, StaffAlert

__all__ = ["AlertBoard"]

log = logging.getLogger("backend.alerts")

EventSink = Callable[[str, dict[str, Any]], None]


class AlertBoard:
    """The active alerts of the server, published as they change."""

    def __init__(self, endpoint: BusEndpoint, on_event: EventSink | None = None) -> None:
        self.endpoint = endpoint
        self.on_event = on_event
        self.active: dict[str, StaffAlert] = {}

    def raise_(
        self,
        alert_id: str,
        kind: AlertKind,
        message: str,
        *,
        severity: Literal["info", "warning", "critical"] = "warning",
        robot: str | None = None,
        area: str | None = None,
        sticky: bool = True,
    ) -> None:
        """Publish an alert; ``sticky`` ones stay active until ``clear``."""
        alert = StaffAlert(
            alert_id=alert_id,
            kind=kind,
            severity=severity,
            active=sticky,
            message=message,
            robot=robot,
            area=area,
            at=time.time(),
        )
        if sticky:
            self.active[alert_id] = alert
        log.warning("staff alert [%s] %s", kind, message)
        self._send(alert)

    def clear(self, alert_id: str, message: str) -> None:
        """The condition is over: publish the alert inactive (nothing if it was not active)."""
        old = self.active.pop(alert_id, None)
        if old is None:
            return
        cleared = old.model_copy(update={"active": False, "message": message, "at": time.time()})
        log.info("staff alert cleared [%s] %s", old.kind, message)
        self._send(cleared)

    def _send(self, alert: StaffAlert) -> None:
        self.endpoint.publish(alert)
        if self.on_event is not None:
            self.on_event("staff_alert", alert.model_dump())
