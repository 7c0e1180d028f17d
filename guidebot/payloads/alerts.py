"""Payload of staff alerts: something a person must look at (docs/messages.md, "Alerts")."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from guidebot.messages import PayloadModel, register_payload

__all__ = ["AlertKind", "StaffAlert"]

AlertKind = Literal[
    "lock_holder_offline",
    "lock_released_offline",
    "area_conflict",
]


@register_payload("staff_alert")
class StaffAlert(PayloadModel):
    """Raised (``active``) and later cleared (same ``alert_id``, ``active`` false) by the server.

    A console keeps the active alerts by ``alert_id``; ``GET /api/alerts`` lists them on load.
    """

    alert_id: str = Field(max_length=128)
    kind: AlertKind
    severity: Literal["info", "warning", "critical"]
    active: bool
    message: str = Field(max_length=500)
    robot: str | None = None
    area: str | None = None
    at: float
