"""The bounded outbound queue of one hub client, with the overflow rule of docs/protocol.md.

Rule: while the client keeps up (fewer than ``coalesce_after`` messages queued) every message is
sent. Once it falls behind, a message with a coalescing key (robot_state: the robot's name)
replaces the newest queued message with the same key in place, so a slow GUI gets the newest
state of every robot and the queue stops growing. Any other message that finds the queue full
raises ``OutboxOverflow``: the hub then disconnects that client with close code 4008 and a
reason. Nothing else is ever dropped silently.
"""

from __future__ import annotations

import asyncio
from collections import deque

__all__ = ["Outbox", "OutboxOverflow"]


class OutboxOverflow(Exception):
    """The client does not read fast enough: its queue is full of messages that cannot merge."""


class Outbox:
    """Serialised messages waiting for one client's writer task."""

    def __init__(self, maxsize: int, coalesce_after: int | None = None) -> None:
        if maxsize < 1:
            raise ValueError("an outbox needs room for at least one message")
        self.maxsize = maxsize
        self.coalesce_after = maxsize // 8 if coalesce_after is None else coalesce_after
        self._items: deque[list[bytes | str | None]] = deque()
        self._by_key: dict[str, list[bytes | str | None]] = {}
        self._ready = asyncio.Event()
        self.queued = 0
        self.superseded = 0
        self.closed = False
        self._more: tuple[asyncio.Future[None], int] | None = None

    def __len__(self) -> int:
        return len(self._items)

    def put(self, data: bytes, key: str | None = None) -> None:
        """Queue one message; raises OutboxOverflow when full and ``data`` cannot merge."""
        if key is not None and len(self._items) >= self.coalesce_after:
            entry = self._by_key.get(key)
            if entry is not None:
                entry[1] = data
                self.superseded += 1
                return
        if len(self._items) >= self.maxsize:
            raise OutboxOverflow(f"outbound queue full ({self.maxsize} messages)")
        entry = [key, data]
        self._items.append(entry)
        if key is not None:
            self._by_key[key] = entry
        self.queued += 1
        if not self._ready.is_set():
            self._ready.set()
        more = self._more
        if more is not None and len(self._items) >= more[1] and not more[0].done():
            more[0].set_result(None)

    def close(self) -> None:
        """Wake the writer for good: ``get_batch`` returns an empty batch once drained."""
        self.closed = True
        self._ready.set()
        if self._more is not None:
            _wake(self._more[0])

    async def wait(self) -> None:
        """Return once a message is queued or the outbox is closed."""
        while not self._items and not self.closed:
            self._ready.clear()
            await self._ready.wait()

    async def linger(self, delay: float, enough: int) -> None:
        """Wait up to ``delay`` for more messages; return early once ``enough`` are queued."""
        if len(self._items) >= enough or self.closed:
            return
        loop = asyncio.get_running_loop()
        future: asyncio.Future[None] = loop.create_future()
        self._more = (future, enough)
        timer = loop.call_later(delay, _wake, future)
        try:
            await future
        finally:
            timer.cancel()
            self._more = None

    def take(self, max_items: int, max_bytes: int = 1 << 18) -> list[bytes]:
        """Up to ``max_items`` queued messages in order, stopping once ``max_bytes`` are taken
        (one message may be larger)."""
        batch: list[bytes] = []
        items = self._items
        size = 0
        while items and len(batch) < max_items and size < max_bytes:
            entry = items.popleft()
            key = entry[0]
            if key is not None and self._by_key.get(key) is entry:  # type: ignore[arg-type]
                del self._by_key[key]  # type: ignore[arg-type]
            batch.append(entry[1])  # type: ignore[arg-type]
            size += len(entry[1])  # type: ignore[arg-type]
        return batch

    async def get_batch(self, max_items: int, max_bytes: int = 1 << 18) -> list[bytes]:
        """Wait for at least one message, then take a batch; empty once closed and drained."""
        await self.wait()
        return self.take(max_items, max_bytes)


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)
