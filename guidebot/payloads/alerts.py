"""Payload of staff alerts: something a person must look at (docs/messages.md, "Alerts").

One alert per cause (``kind`` and ``subject``): raised again while it is active it counts
(``count``, ``last_seen``) instead of adding a row; it resolves itself when its cause is gone.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from guidebot.messages import PayloadModel, register_payload

__all__ = ["AlertPayload", "AlertSeverity"]

AlertSeverity = Literal["warning", "error"]


@register_payload("alert_raised")
@register_payload("alert_acked")
@register_payload("alert_resolved")
class AlertPayload(PayloadModel):
    """An alert after a change: raised (or seen again), acknowledged, or resolved."""

    id: str = Field(max_length=64)
    kind: str = Field(max_length=64)
    subject: str = Field(max_length=200)
    """What it is about: a robot, an area, a module, ``R1/bumper``, ``call_elevator:lift``."""
    message: str = Field(max_length=500)
    severity: AlertSeverity
    raised_at: float
    last_seen: float
    count: int = Field(ge=1)
    lasting: bool = True
    """True: resolved when its cause is gone; false (an event, e.g. a failed task): resolved
    when acknowledged."""
    acked_by: str | None = None
    acked_at: float | None = None
    resolved_at: float | None = None
    resolution: str | None = None
    """Why it resolved itself (a sentence), or who acknowledged an event alert."""
    updated_at: float
    """The last change: a page merging a snapshot with live messages keeps the newer."""
