"""Payloads the staff console listens to: area locks, its own alerts and the event log as it is
written (docs/messages.md, "Staff console")."""

from __future__ import annotations

from typing import Any, Literal

from guidebot.messages import PayloadModel, register_payload

__all__ = ["ConsoleAlert", "EventLogged", "LockChanged"]


@register_payload("lock_changed")
class LockChanged(PayloadModel):
    """One area lock after a change (the console diffs the Traffic Manager's lock views)."""

    area: str
    state: Literal["free", "held", "holder_offline", "yielding"]
    holder: str | None = None
    since: float | None = None
    entered: bool = False
    waiting: list[str] = []


@register_payload("alert_raised")
@register_payload("alert_acked")
class ConsoleAlert(PayloadModel):
    """An alert of the console's alert book, when it is raised and when someone acknowledges it."""

    id: str
    kind: str
    subject: str
    message: str
    severity: Literal["warning", "error"]
    raised_at: float
    acked_by: str | None = None
    acked_at: float | None = None


@register_payload("event_logged")
class EventLogged(PayloadModel):
    """One row of the event log, as it is written."""

    at: float
    kind: str
    source: str
    data: dict[str, Any]
