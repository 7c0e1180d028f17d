"""In-process publish/subscribe: the on-board bus of a robot and the core of the server hub.

Delivery rules (docs/protocol.md):
- a message without destination goes to every subscription whose pattern matches its type;
- a message with a destination goes only to that endpoint's matching subscriptions, and to
  taps (monitors that see all traffic);
- a message with a correlation id also completes the sender's pending ``request`` with that id.

Handlers are plain callables run inline by ``publish``: they must not block. A handler that
raises is logged and skipped; it never breaks delivery to the others.
"""

from __future__ import annotations

import asyncio
import contextlib
import fnmatch
import logging
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

from guidebot.messages import Message

__all__ = [
    "Bus",
    "BusEndpoint",
    "Endpoint",
    "Handler",
    "RequestTimeout",
    "Subscription",
    "pattern_matches",
]

log = logging.getLogger(__name__)

Handler = Callable[[Message], None]


class RequestTimeout(TimeoutError):
    """No reply arrived in time for a request."""


def is_wildcard(pattern: str) -> bool:
    return any(ch in pattern for ch in "*?[")


def pattern_matches(pattern: str, message_type: str) -> bool:
    """Shell-style wildcards over message types: ``*``, ``building_*``, ``robot_?tate``."""
    return pattern == message_type or (
        is_wildcard(pattern) and fnmatch.fnmatchcase(message_type, pattern)
    )


class BusEndpoint(Protocol):
    """What a module needs from a bus: the Petri-net engine, drivers and managers use only this."""

    name: str

    def publish(
        self,
        type: str,
        payload: dict[str, Any] | None = None,
        *,
        destination: str | None = None,
        correlation_id: str | None = None,
    ) -> Message: ...

    def send(self, message: Message) -> None: ...

    def subscribe(self, pattern: str, handler: Handler) -> Callable[[], None]: ...

    async def request(
        self,
        type: str,
        payload: dict[str, Any] | None = None,
        *,
        destination: str | None = None,
        timeout: float = 2.0,
    ) -> Message: ...


@dataclass(eq=False)
class Subscription:
    pattern: str
    handler: Handler
    endpoint: Endpoint
    tap: bool = False
    wild: bool = field(init=False)

    def __post_init__(self) -> None:
        self.wild = is_wildcard(self.pattern)


@dataclass(eq=False)
class Endpoint:
    """A named client of the bus: an in-process module, or the proxy of a remote client."""

    name: str
    bus: Bus
    _subscriptions: list[Subscription] = field(default_factory=list)
    _pending: dict[str, asyncio.Future[Message]] = field(default_factory=dict)
    closed: bool = False

    def publish(
        self,
        type: str,
        payload: dict[str, Any] | None = None,
        *,
        destination: str | None = None,
        correlation_id: str | None = None,
    ) -> Message:
        message = Message(
            type=type,
            source=self.name,
            destination=destination,
            correlation_id=correlation_id,
            payload=payload or {},
        )
        self.bus.publish(message)
        return message

    def send(self, message: Message) -> None:
        """Publish a ready-made message, stamped with this endpoint as its source."""
        if message.source != self.name:
            message = message.model_copy(update={"source": self.name})
        self.bus.publish(message)

    def reply(self, request: Message, type: str, payload: dict[str, Any] | None = None) -> Message:
        message = request.reply(type, payload, source=self.name)
        self.bus.publish(message)
        return message

    def subscribe(self, pattern: str, handler: Handler, *, tap: bool = False) -> Callable[[], None]:
        """Call ``handler`` for matching messages; returns the function that unsubscribes.

        A tap also sees messages addressed to other endpoints (monitoring, logging).
        """
        sub = Subscription(pattern, handler, self, tap)
        self._subscriptions.append(sub)
        self.bus._add(sub)

        def unsubscribe() -> None:
            if sub in self._subscriptions:
                self._subscriptions.remove(sub)
                self.bus._remove(sub)

        return unsubscribe

    @contextlib.asynccontextmanager
    async def subscription(
        self, pattern: str, *, maxsize: int = 1000
    ) -> AsyncIterator[AsyncIterator[Message]]:
        """``async with ep.subscription("x") as sub: async for msg in sub``.

        The queue is bounded: on overflow the oldest message is dropped (and logged), so a slow
        reader can never grow memory without limit.
        """
        queue: asyncio.Queue[Message] = asyncio.Queue(maxsize=maxsize)

        def put(message: Message) -> None:
            if queue.full():
                queue.get_nowait()
                log.warning(
                    "%s: subscription %r overflowed, oldest message dropped", self.name, pattern
                )
            queue.put_nowait(message)

        unsubscribe = self.subscribe(pattern, put)

        async def iterate() -> AsyncIterator[Message]:
            while True:
                yield await queue.get()

        try:
            yield iterate()
        finally:
            unsubscribe()

    async def request(
        self,
        type: str,
        payload: dict[str, Any] | None = None,
        *,
        destination: str | None = None,
        timeout: float = 2.0,
    ) -> Message:
        """Publish and wait for the message whose correlation id is this one's id."""
        message = Message(
            type=type, source=self.name, destination=destination, payload=payload or {}
        )
        future: asyncio.Future[Message] = asyncio.get_running_loop().create_future()
        self._pending[message.id] = future
        try:
            self.bus.publish(message)
            # asyncio.timeout, not wait_for: on Python 3.11 wait_for returns a reply that
            # arrives in the same loop pass as a cancellation, and the caller never sees it.
            async with asyncio.timeout(timeout):
                return await future
        except TimeoutError:
            raise RequestTimeout(f"no reply to {type!r} within {timeout} s") from None
        finally:
            self._pending.pop(message.id, None)

    def _resolve(self, message: Message) -> bool:
        future = self._pending.get(message.correlation_id or "")
        if future is None or future.done():
            return False
        future.set_result(message)
        return True

    def close(self) -> None:
        for sub in list(self._subscriptions):
            self.bus._remove(sub)
        self._subscriptions.clear()
        for future in self._pending.values():
            if not future.done():
                future.cancel()
        self._pending.clear()
        self.closed = True
        self.bus._endpoints.pop(self.name, None)


class Bus:
    """The router. Exact-type subscriptions are looked up in a dict; wildcards are scanned."""

    def __init__(self) -> None:
        self._exact: dict[str, list[Subscription]] = {}
        self._wild: list[Subscription] = []
        self._endpoints: dict[str, Endpoint] = {}
        self.published = 0

    def endpoint(self, name: str) -> Endpoint:
        """Register a named client; names are unique while connected."""
        if name in self._endpoints:
            raise ValueError(f"an endpoint named {name!r} is already connected")
        ep = Endpoint(name=name, bus=self)
        self._endpoints[name] = ep
        return ep

    def get_endpoint(self, name: str) -> Endpoint | None:
        return self._endpoints.get(name)

    @property
    def endpoint_names(self) -> list[str]:
        return list(self._endpoints)

    def publish(self, message: Message) -> int:
        """Deliver a message; returns how many handlers received it."""
        self.published += 1
        delivered = 0
        if message.correlation_id is not None:
            target = self._endpoints.get(message.destination or "")
            if target is not None and target._resolve(message):
                delivered += 1
        candidates = self._exact.get(message.type, ())
        for sub in (*candidates, *self._wild) if self._wild else candidates:
            if sub.endpoint.closed:
                continue
            if (
                message.destination is not None
                and not sub.tap
                and sub.endpoint.name != message.destination
            ):
                continue
            if sub.wild and not fnmatch.fnmatchcase(message.type, sub.pattern):
                continue
            try:
                sub.handler(message)
            except Exception:
                log.exception("handler of %s for %r failed", sub.endpoint.name, message.type)
            delivered += 1
        return delivered

    def _add(self, sub: Subscription) -> None:
        if sub.wild:
            self._wild.append(sub)
        else:
            self._exact.setdefault(sub.pattern, []).append(sub)

    def _remove(self, sub: Subscription) -> None:
        if sub.wild:
            if sub in self._wild:
                self._wild.remove(sub)
        else:
            subs = self._exact.get(sub.pattern)
            if subs and sub in subs:
                subs.remove(sub)
                if not subs:
                    del self._exact[sub.pattern]
