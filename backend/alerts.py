"""Staff alerts: conditions a person must look at, as ``staff_alert`` messages on the hub, a
warning in the log and a row in the event log (docs/messages.md, "Alerts").

An alert is raised once under a stable ``alert_id`` and cleared under the same id, so a console
that keeps the active ones by id shows each condition once, however often it is re-checked.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Any

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
        self.active: dict[str, dict[str, Any]] = {}

    def raise_(
        self,
        alert_id: str,
        kind: AlertKind,
        message: str,
        *,
        severity: str = "warning",
        robot: str | None = None,
        area: str | None = None,
        sticky: bool = True,
    ) -> None:
        """Publish an alert; ``sticky`` ones stay active until ``clear``."""
        payload = StaffAlert.model_validate(
            {
                "alert_id": alert_id,
                "kind": kind,
                "severity": severity,
                "active": sticky,
                "message": message,
                "robot": robot,
                "area": area,
                "at": time.time(),
            }
        ).model_dump()
        if sticky:
            self.active[alert_id] = payload
        log.warning("staff alert [%s] %s", kind, message)
        self._send(payload)

    def clear(self, alert_id: str, message: str) -> None:
        """The condition is over: publish the alert inactive (nothing if it was not active)."""
        old = self.active.pop(alert_id, None)
        if old is None:
            return
        payload = {**old, "active": False, "message": message, "at": time.time()}
        log.info("staff alert cleared [%s] %s", old["kind"], message)
        self._send(payload)

    def _send(self, payload: dict[str, Any]) -> None:
        self.endpoint.publish("staff_alert", payload)
        if self.on_event is not None:
            self.on_event("staff_alert", payload)
