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

from pydantic import BaseModel

from backend.state import app_state
from guidebot.bus import BusEndpoint, Endpoint, Handler
from guidebot.messages import Message, Payload, type_name

__all__ = ["FencedEndpoint", "deciding_endpoint"]

log = logging.getLogger(__name__)


class FencedEndpoint(BusEndpoint):
    """A bus endpoint that passes nothing in or out while ``may_decide()`` is false."""

    def __init__(self, inner: Endpoint, may_decide: Callable[[], bool]) -> None:
        self.inner = inner
        self.name = inner.name
        self._pending = inner._pending  # replies reach the inner endpoint
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

    def _transmit(self, message: Message) -> None:
        if not self._fenced("send", message.type):
            self.inner._transmit(message)

    def subscribe(self, pattern: str, handler: Handler, **options: Any) -> Callable[[], None]:
        def gated(message: Message) -> None:
            if not self._fenced("handle", message.type):
                handler(message)

        return self.inner.subscribe(pattern, gated, **options)

    async def request(
        self,
        type: str | BaseModel,
        payload: Payload = None,
        *,
        destination: str | None = None,
        timeout: float = 2.0,
    ) -> Message:
        if self._fenced("send", type if isinstance(type, str) else type_name(type.__class__)):
            raise TimeoutError(f"{self.name}: this process's lease ran out; request not sent")
        return await super().request(type, payload, destination=destination, timeout=timeout)

    def close(self) -> None:
        self.inner.close()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def deciding_endpoint(app: Any, name: str) -> Endpoint | FencedEndpoint:
    """The hub endpoint ``name`` for a deciding component: fenced on a clustered server."""
    endpoint: Endpoint = app.state.hub.endpoint(name)
    leadership = app_state(app).leadership
    if leadership is None:
        return endpoint
    fenced = FencedEndpoint(endpoint, leadership.may_decide)
    app.state.fenced_endpoints = [*app_state(app).fenced_endpoints, fenced]
    return fenced
