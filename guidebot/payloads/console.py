"""Payloads the staff console listens to: area locks and the event log as it is written
(docs/messages.md, "Staff console"; alerts: guidebot/payloads/alerts.py)."""

from __future__ import annotations

from typing import Any, Literal

from guidebot.messages import PayloadModel, register_payload

__all__ = ["EventLogged", "LockChanged"]


@register_payload("lock_changed")
class LockChanged(PayloadModel):
    """One area lock after a change (the console diffs the Traffic Manager's lock views)."""

    area: str
    state: Literal["free", "held", "holder_offline", "yielding"]
    holder: str | None = None
    since: float | None = None
    entered: bool = False
    waiting: list[str] = []


@register_payload("event_logged")
class EventLogged(PayloadModel):
    """One row of the event log, as it is written."""

    at: float
    kind: str
    source: str
    data: dict[str, Any]
