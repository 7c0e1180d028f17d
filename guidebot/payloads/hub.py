"""Payload models of the hub's own messages: errors, subscriptions, heartbeats."""

from __future__ import annotations

from guidebot.messages import PayloadModel, register_payload


@register_payload("error")
class Error(PayloadModel):
    """Sent to a client whose message was refused; the connection stays up."""

    code: str
    reason: str
    message_id: str | None = None


@register_payload("ping")
class Ping(PayloadModel):
    pass


@register_payload("pong")
class Pong(PayloadModel):
    pass
