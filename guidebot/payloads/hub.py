"""Payload models of the hub's own messages: errors, subscriptions, heartbeats, welcome."""

from __future__ import annotations

from pydantic import Field

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


@register_payload("subscribe")
class Subscribe(PayloadModel):
    """Client -> hub: deliver messages whose type matches any of these patterns (wildcards)."""

    patterns: list[str] = Field(min_length=1, max_length=256)


@register_payload("unsubscribe")
class Unsubscribe(PayloadModel):
    patterns: list[str] = Field(min_length=1, max_length=256)


@register_payload("welcome")
class Welcome(PayloadModel):
    """Hub -> client after authentication: the name the hub stamps on its messages."""

    name: str
    role: str


@register_payload("ack")
class Ack(PayloadModel):
    """A must-arrive message was received (guidebot/delivery.py): stop sending it again."""

    message_id: str = Field(min_length=1, max_length=64)
