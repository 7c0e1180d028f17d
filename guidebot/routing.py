"""Subscriptions by message-type pattern, and requests waiting for their reply.

Written once for the in-process bus (guidebot/bus.py) and the hub's client library
(guidebot/client.py): the same wildcard rule, the same reply-by-correlation-id rule, the same
time-out error.
"""

from __future__ import annotations

import asyncio
import fnmatch
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Generic, TypeVar

from guidebot.messages import Message

__all__ = [
    "Handler",
    "PatternTable",
    "PendingRequests",
    "RequestTimeout",
    "Route",
    "is_wildcard",
    "pattern_matches",
]

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


@dataclass(eq=False)
class Route:
    """A handler for the message types a pattern matches."""

    pattern: str
    handler: Handler
    wild: bool = field(init=False)

    def __post_init__(self) -> None:
        self.wild = is_wildcard(self.pattern)


R = TypeVar("R", bound=Route)


class PatternTable(Generic[R]):
    """Routes by pattern: exact types looked up in a dict, wildcards scanned.

    Tuples are replaced, never mutated, so a handler may subscribe or unsubscribe while a
    message is being delivered. The routes of each type are remembered until the table
    changes: a hub with "*" taps matches a type's wildcards once, not once per message.

    ``distinct`` (for example the WebSocket client a hub route belongs to): of the routes a
    type matches, only the first with each key is kept, so a client whose patterns overlap
    (``robot_state`` and ``*``) gets a message once. Worked out once per type, as the rest.
    """

    CACHE_TYPES = 1024
    """Types remembered at most (the on-board bus carries any type a net publishes)."""

    def __init__(self, *, distinct: Callable[[R], object] | None = None) -> None:
        self._distinct = distinct
        self._exact: dict[str, tuple[R, ...]] = {}
        self._wild: dict[str, tuple[R, ...]] = {}
        self._wild_routes: tuple[R, ...] = ()
        self._cache: dict[str, tuple[R, ...]] = {}

    def add(self, route: R) -> bool:
        """Add a route; True if it is the first for its pattern."""
        table = self._wild if route.wild else self._exact
        routes = table.get(route.pattern, ())
        table[route.pattern] = (*routes, route)
        if route.wild:
            self._wild_routes = (*self._wild_routes, route)
        self._cache.clear()
        return not routes

    def remove(self, route: R) -> bool:
        """Remove a route (absent: nothing happens); True if its pattern has no route left."""
        table = self._wild if route.wild else self._exact
        routes = table.get(route.pattern, ())
        if route not in routes:
            return False
        left = tuple(r for r in routes if r is not route)
        if left:
            table[route.pattern] = left
        else:
            del table[route.pattern]
        if route.wild:
            self._wild_routes = tuple(r for r in self._wild_routes if r is not route)
        self._cache.clear()
        return not left

    def matching(self, message_type: str) -> tuple[R, ...]:
        """The routes for a type, exact ones first, each in the order it was added."""
        routes = self._cache.get(message_type)
        if routes is not None:
            return routes
        routes = self._exact.get(message_type, ())
        if self._wild_routes:
            matched = [r for r in self._wild_routes if fnmatch.fnmatchcase(message_type, r.pattern)]
            if matched:
                routes = (*routes, *matched)
        if self._distinct is not None and len(routes) > 1:
            routes = _first_per_key(routes, self._distinct)
        if len(self._cache) >= self.CACHE_TYPES:
            self._cache.clear()
        self._cache[message_type] = routes
        return routes

    def patterns(self) -> list[str]:
        """Every pattern with at least one route."""
        return [*self._exact, *self._wild]


def _first_per_key(routes: tuple[R, ...], key: Callable[[R], object]) -> tuple[R, ...]:
    seen: set[object] = set()
    kept: list[R] = []
    for route in routes:
        k = key(route)
        if k not in seen:
            seen.add(k)
            kept.append(route)
    return tuple(kept)


class PendingRequests:
    """Requests sent and waiting for the message whose correlation id is their id."""

    def __init__(self) -> None:
        self._futures: dict[str, asyncio.Future[Message]] = {}

    def values(self) -> list[asyncio.Future[Message]]:
        return list(self._futures.values())

    async def wait(
        self, message: Message, send: Callable[[Message], object], timeout: float
    ) -> Message:
        """Send ``message`` and wait for its reply; raises RequestTimeout after ``timeout``."""
        future: asyncio.Future[Message] = asyncio.get_running_loop().create_future()
        self._futures[message.id] = future
        try:
            send(message)
            # asyncio.timeout, not wait_for: on Python 3.11 wait_for returns a reply that
            # arrives in the same loop pass as a cancellation, and the caller never sees it.
            async with asyncio.timeout(timeout):
                return await future
        except TimeoutError:
            raise RequestTimeout(f"no reply to {message.type!r} within {timeout} s") from None
        finally:
            self._futures.pop(message.id, None)

    def resolve(self, message: Message) -> bool:
        """Complete the request this message answers; False if none is waiting for it."""
        future = self._futures.get(message.correlation_id or "")
        if future is None or future.done():
            return False
        future.set_result(message)
        return True

    def cancel_all(self) -> None:
        for future in self._futures.values():
            if not future.done():
                future.cancel()
        self._futures.clear()
