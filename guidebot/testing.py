"""Test helpers every package's tests share: a bus message recorder and waiting on a condition.

Tests wait on conditions with generous time-outs, never sleep-and-assert (the machine running
them may be loaded); the recorder wakes its waiters on every message, so a wait costs nothing
while the condition is false.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any

from guidebot.bus import Endpoint
from guidebot.messages import Message

__all__ = ["Recorder", "wait_on", "wait_until"]


class Recorder:
    """Every message of some types seen on a bus (``tap``: also those addressed to others)."""

    def __init__(self, endpoint: Endpoint, *patterns: str, tap: bool = False) -> None:
        self.messages: list[Message] = []
        self._changed = asyncio.Event()
        for pattern in patterns:
            endpoint.subscribe(pattern, self._add, tap=tap)

    def _add(self, message: Message) -> None:
        self.messages.append(message)
        self._changed.set()

    def of(self, type_: str, **fields: Any) -> list[Message]:
        """The messages of a type whose payload has these field values, oldest first."""
        return [
            m
            for m in self.messages
            if m.type == type_ and all(m.payload.get(k) == v for k, v in fields.items())
        ]

    async def wait_for(self, predicate: Callable[[], bool], timeout: float = 20.0) -> None:
        """Until ``predicate()`` holds, checked after every message; TimeoutError after that."""
        await wait_on(self._changed, predicate, timeout)

    async def wait(
        self,
        type_: str,
        predicate: Callable[[Message], bool] | None = None,
        timeout: float = 10.0,
        **fields: Any,
    ) -> Message:
        """The first message (already seen or still to come) of a type with these payload
        fields that ``predicate`` accepts; TimeoutError naming the type after ``timeout``."""
        found: list[Message] = []

        def seen() -> bool:
            found[:] = [m for m in self.of(type_, **fields) if predicate is None or predicate(m)]
            return bool(found)

        try:
            await self.wait_for(seen, timeout)
        except TimeoutError:
            raise TimeoutError(f"no {type_} matching the condition within {timeout} s") from None
        return found[0]


async def wait_on(changed: asyncio.Event, predicate: Callable[[], Any], timeout: float) -> None:
    """Until ``predicate()`` holds, checked each time ``changed`` is set (by whoever records
    what the predicate reads); TimeoutError after ``timeout`` seconds."""
    async with asyncio.timeout(timeout):
        while not predicate():
            changed.clear()
            if predicate():
                return
            await changed.wait()


async def wait_until(condition: Callable[[], bool], timeout: float = 10.0) -> None:
    """Poll a condition every 10 ms, for state that announces itself with no message."""
    async with asyncio.timeout(timeout):
        while not condition():  # noqa: ASYNC110 - the state polled here emits no event
            await asyncio.sleep(0.01)
