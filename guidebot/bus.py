"""In-process publish/subscribe: the on-board bus of a robot and the core of the server hub.

Delivery rules (docs/protocol.md):
- a message without destination goes to every subscription whose pattern matches its type;
- a message with a destination goes only to that endpoint's matching subscriptions, and to
  taps (monitors that see all traffic);
- a message with a correlation id also completes the sender's pending ``request`` with that id.

Handlers are plain callables run inline by ``publish``: they must not block. A handler that
raises is logged and skipped; it never breaks delivery to the others.

Two ways to subscribe: by payload model, ``ep.on(RequestArea, handler)``, the handler getting
``(message, payload)`` with ``payload`` a ``RequestArea`` (the one the message carries, typed
once: guidebot/messages.py); or by type pattern, ``ep.subscribe("building_*", handler)``, the
handler getting the message and reading ``message.payload`` as JSON (taps, wildcards, relays).
A payload that is not its model never reaches a typed handler: it is logged and dropped.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import AsyncIterator, Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from guidebot.messages import Message, Payload, make_message, type_names
from guidebot.queues import KeyedQueue
from guidebot.routing import (
    Handler,
    PatternTable,
    PendingRequests,
    RequestTimeout,
    Route,
    is_wildcard,
    pattern_matches,
)

__all__ = [
    "Bus",
    "BusEndpoint",
    "Endpoint",
    "Handler",
    "RequestTimeout",
    "Subscription",
    "TypedHandler",
    "is_wildcard",
    "pattern_matches",
    "typed_handler",
]

log = logging.getLogger(__name__)

M = TypeVar("M", bound=BaseModel)

TypedHandler = Callable[[Message, M], object]
"""A handler subscribed by payload model: the message and its payload as that model."""


def typed_handler(model: type[M], handler: TypedHandler[M], where: str = "") -> Handler:
    """The plain handler that gives ``handler`` the message's payload as ``model``; a payload
    that is not one is logged (by ``where``, the subscriber) and never reaches ``handler``."""

    def deliver(message: Message) -> None:
        try:
            payload = message.typed(model)
        except ValidationError as exc:
            log.warning(
                "%s: dropped %r from %r: its payload is not a %s: %s",
                where or handler,
                message.type,
                message.source,
                model.__name__,
                exc.errors()[:3],
            )
            return
        handler(message, payload)

    return deliver


@contextlib.asynccontextmanager
async def bounded_subscription(
    endpoint: BusEndpoint, pattern: str, maxsize: int
) -> AsyncIterator[AsyncIterator[Message]]:
    """``subscription()`` of every endpoint: a bounded queue that drops its oldest message on
    overflow (logged), so a slow reader can never grow memory without limit."""
    queue: KeyedQueue[Message] = KeyedQueue(
        maxsize, drop_oldest=True, name=f"{endpoint.name}: subscription {pattern!r}"
    )
    unsubscribe = endpoint.subscribe(pattern, queue.put)
    try:
        yield queue
    finally:
        unsubscribe()
        queue.close()


class BusEndpoint:
    """What a module needs from a bus: the Petri-net engine, drivers and managers use only this.

    Senders publish payload models (``ep.publish(RequestArea(robot=..., area=...))``): the type
    name comes with the model, so searching for the class finds sender and receiver alike. A
    type name and a dict payload are still accepted.

    publish, send, reply, request and subscription are written here once, for the in-process
    ``Endpoint`` and the WebSocket ``HubClient`` alike, over the two methods each provides:
    ``_transmit`` (hand a message on) and ``subscribe``.
    """

    name: str
    _pending: PendingRequests

    def _transmit(self, message: Message) -> None:
        raise NotImplementedError

    def subscribe(self, pattern: str, handler: Handler) -> Callable[[], None]:
        raise NotImplementedError

    def on(
        self,
        model: type[M],
        handler: TypedHandler[M],
        *,
        types: Iterable[str] | None = None,
        **options: Any,
    ) -> Callable[[], None]:
        """Call ``handler(message, payload)`` for every message whose payload is ``model``;
        returns the function that unsubscribes. Every type the model is registered for, or
        the ``types`` given (``RobotLink``: only "robot_disconnected"). ``options`` go to
        ``subscribe`` (``tap=True`` on the in-process bus)."""
        names = type_names(model)
        if types is not None:
            wanted = tuple(types)
            if not wanted or not set(wanted) <= set(names):
                raise ValueError(f"{model.__name__} is the payload of {names}, not of {wanted}")
            names = wanted
        deliver = typed_handler(model, handler, self.name)
        stops = [self.subscribe(name, deliver, **options) for name in names]
        if len(stops) == 1:
            return stops[0]

        def unsubscribe() -> None:
            for stop in stops:
                stop()

        return unsubscribe

    def publish(
        self,
        type: str | BaseModel,
        payload: Payload = None,
        *,
        destination: str | None = None,
        correlation_id: str | None = None,
    ) -> Message:
        message = make_message(
            type,
            payload,
            source=self.name,
            destination=destination,
            correlation_id=correlation_id,
        )
        self._transmit(message)
        return message

    def send(self, message: Message) -> None:
        """Publish a ready-made message, stamped with this endpoint as its source."""
        if message.source != self.name:
            typed = message.typed_or_none()
            message = message.model_copy(update={"source": self.name})
            if typed is not None:
                message.keep_typed(typed)
        self._transmit(message)

    def reply(self, request: Message, type: str | BaseModel, payload: Payload = None) -> Message:
        message = request.reply(type, payload, source=self.name)
        self._transmit(message)
        return message

    def subscription(
        self, pattern: str, *, maxsize: int = 1000
    ) -> contextlib.AbstractAsyncContextManager[AsyncIterator[Message]]:
        """``async with ep.subscription("x") as sub: async for msg in sub`` (bounded: the
        oldest message is dropped on overflow, and logged)."""
        return bounded_subscription(self, pattern, maxsize)

    async def request(
        self,
        type: str | BaseModel,
        payload: Payload = None,
        *,
        destination: str | None = None,
        timeout: float = 2.0,
    ) -> Message:
        """Publish and wait for the message whose correlation id is this one's id."""
        message = make_message(type, payload, source=self.name, destination=destination)
        return self._check_reply(await self._pending.wait(message, self._transmit, timeout))

    def _check_reply(self, reply: Message) -> Message:
        return reply


@dataclass(eq=False)
class Subscription(Route):
    endpoint: Endpoint = field(kw_only=True)
    tap: bool = field(default=False, kw_only=True)


@dataclass(eq=False)
class Endpoint(BusEndpoint):
    """A named client of the bus: an in-process module, or the proxy of a remote client."""

    name: str
    bus: Bus
    _subscriptions: list[Subscription] = field(default_factory=list)
    _pending: PendingRequests = field(default_factory=PendingRequests)
    closed: bool = False

    def _transmit(self, message: Message) -> None:
        self.bus.publish(message)

    def subscribe(self, pattern: str, handler: Handler, *, tap: bool = False) -> Callable[[], None]:
        """Call ``handler`` for matching messages; returns the function that unsubscribes.

        A tap also sees messages addressed to other endpoints (monitoring, logging).
        """
        sub = Subscription(pattern, handler, endpoint=self, tap=tap)
        self._subscriptions.append(sub)
        self.bus.routes.add(sub)

        def unsubscribe() -> None:
            if sub in self._subscriptions:
                self._subscriptions.remove(sub)
                self.bus.routes.remove(sub)

        return unsubscribe

    def close(self) -> None:
        for sub in self._subscriptions:
            self.bus.routes.remove(sub)
        self._subscriptions.clear()
        self._pending.cancel_all()
        self.closed = True
        self.bus._endpoints.pop(self.name, None)


class Bus:
    """The router: one PatternTable of every endpoint's subscriptions."""

    def __init__(self) -> None:
        self.routes: PatternTable[Subscription] = PatternTable()
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
            if target is not None and target._pending.resolve(message):
                delivered += 1
        for sub in self.routes.matching(message.type):
            if sub.endpoint.closed:
                continue
            if (
                message.destination is not None
                and not sub.tap
                and sub.endpoint.name != message.destination
            ):
                continue
            try:
                sub.handler(message)
            except Exception:
                log.exception("handler of %s for %r failed", sub.endpoint.name, message.type)
            delivered += 1
        return delivered
