"""Fencing for the deciding components on a clustered server (docs/scaling.md).

Task Manager, Traffic Manager and BuildingInterface decide through their bus endpoint: a grant,
an assignment or a door command is a message they send, or a Modbus write they make while
handling a message. On a clustered server each of them gets a ``FencedEndpoint``: before every
message it hands to them and before every message they send, it asks the leadership whether this
process may still decide (it leads and its lease runs). A leader that was paused, frozen or cut
off past its lease therefore handles and sends nothing, even before it notices that it lost the
lock; what it drops is counted and logged. Without a broker the plain endpoint is used.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from guidebot.bus import Endpoint, Handler
from guidebot.messages import Message

__all__ = ["FencedEndpoint", "deciding_endpoint"]

log = logging.getLogger(__name__)


class FencedEndpoint:
    """A bus endpoint that passes nothing in or out while ``may_decide()`` is false."""

    def __init__(self, inner: Any, may_decide: Callable[[], bool]) -> None:
        self.inner = inner
        self.name: str = inner.name
        self.may_decide = may_decide
        self.dropped = 0
        """Messages not handled or not sent because the lease had run out."""

    def _fenced(self, what: str, message_type: str) -> bool:
        if self.may_decide():
            return False
        self.dropped += 1
        log.warning(
            "fencing: %s did not %s %s: this process's lease ran out", self.name, what, message_type
        )
        return True

    def publish(
        self,
        type: str,
        payload: dict[str, Any] | None = None,
        *,
        destination: str | None = None,
        correlation_id: str | None = None,
    ) -> Message:
        if self._fenced("send", type):
            return Message(
                type=type,
                source=self.name,
                destination=destination,
                correlation_id=correlation_id,
                payload=payload or {},
            )
        message: Message = self.inner.publish(
            type, payload, destination=destination, correlation_id=correlation_id
        )
        return message

    def send(self, message: Message) -> None:
        if not self._fenced("send", message.type):
            self.inner.send(message)

    def reply(self, request: Message, type: str, payload: dict[str, Any] | None = None) -> Message:
        if self._fenced("send", type):
            return request.reply(type, payload, source=self.name)
        reply: Message = self.inner.reply(request, type, payload)
        return reply

    def subscribe(self, pattern: str, handler: Handler, **options: Any) -> Callable[[], None]:
        def gated(message: Message) -> None:
            if not self._fenced("handle", message.type):
                handler(message)

        unsubscribe: Callable[[], None] = self.inner.subscribe(pattern, gated, **options)
        return unsubscribe

    async def request(
        self,
        type: str,
        payload: dict[str, Any] | None = None,
        *,
        destination: str | None = None,
        timeout: float = 2.0,
    ) -> Message:
        if self._fenced("send", type):
            raise TimeoutError(f"{self.name}: this process's lease ran out; {type} not sent")
        answer: Message = await self.inner.request(
            type, payload, destination=destination, timeout=timeout
        )
        return answer

    def close(self) -> None:
        self.inner.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def deciding_endpoint(app: Any, name: str) -> Endpoint | FencedEndpoint:
    """The hub endpoint ``name`` for a deciding component: fenced on a clustered server."""
    endpoint: Endpoint = app.state.hub.endpoint(name)
    leadership = getattr(app.state, "leadership", None)
    if leadership is None:
        return endpoint
    fenced = FencedEndpoint(endpoint, leadership.may_decide)
    app.state.fenced_endpoints = [*getattr(app.state, "fenced_endpoints", []), fenced]
    return fenced
