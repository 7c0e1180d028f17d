"""The one bounded queue of the bus: keyed merging, batching, and a stated overflow rule.

Used for a hub client's outbox (backend/hub/outbox.py), a HubClient's send queue, a bus
``subscription()`` and the touch screen's pushes. Rules:

- merging: once ``coalesce_after`` items are queued, an item with a key (robot_state: its robot)
  replaces the queued item with the same key in place instead of queuing behind it, so the
  reader gets the newest value and the queue stops growing (``superseded`` counts them);
- overflow: a full queue either raises ``QueueOverflow`` (nothing queued is lost; the hub then
  disconnects the slow client) or, with ``drop_oldest``, drops its oldest item (counted in
  ``dropped`` and logged) so a slow reader can never grow memory without limit;
- batching: ``take`` hands the writer everything already queued, up to a count and a size.
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from typing import Any, Generic, TypeVar

__all__ = ["KeyedQueue", "QueueOverflow"]

log = logging.getLogger(__name__)

T = TypeVar("T")


class QueueOverflow(Exception):
    """The queue is full of items that cannot merge, and it does not drop the oldest."""


class KeyedQueue(Generic[T]):
    """A bounded FIFO of items, optionally keyed; an async iterator over its items."""

    def __init__(
        self,
        maxsize: int,
        *,
        coalesce_after: int = 0,
        drop_oldest: bool = False,
        name: str = "queue",
    ) -> None:
        if maxsize < 1:
            raise ValueError("a queue needs room for at least one item")
        self.maxsize = maxsize
        self.coalesce_after = coalesce_after
        self.drop_oldest = drop_oldest
        self.name = name
        # Entries are [key, item] lists: merging replaces the item in place.
        self._items: deque[list[Any]] = deque()
        self._by_key: dict[str, list[Any]] = {}
        self._ready = asyncio.Event()
        self._more: tuple[asyncio.Future[None], int] | None = None
        self.queued = 0
        self.superseded = 0
        self.dropped = 0
        self.closed = False

    def __len__(self) -> int:
        return len(self._items)

    def put(self, item: T, key: str | None = None) -> None:
        """Queue one item; a full queue drops its oldest or raises QueueOverflow."""
        if key is not None and len(self._items) >= self.coalesce_after:
            entry = self._by_key.get(key)
            if entry is not None:
                entry[1] = item
                self.superseded += 1
                return
        if len(self._items) >= self.maxsize:
            if not self.drop_oldest:
                raise QueueOverflow(f"outbound queue full ({self.maxsize} messages)")
            self._forget(self._items.popleft())
            self.dropped += 1
            log.warning("%s: queue full (%d), oldest item dropped", self.name, self.maxsize)
        entry = [key, item]
        self._items.append(entry)
        if key is not None:
            self._by_key[key] = entry
        self.queued += 1
        if not self._ready.is_set():
            self._ready.set()
        more = self._more
        if more is not None and len(self._items) >= more[1] and not more[0].done():
            more[0].set_result(None)

    def _forget(self, entry: list[Any]) -> None:
        key = entry[0]
        if key is not None and self._by_key.get(key) is entry:
            del self._by_key[key]

    def close(self) -> None:
        """Wake the reader for good: once drained, batches are empty and iteration ends."""
        self.closed = True
        self._ready.set()
        if self._more is not None:
            _wake(self._more[0])

    async def wait(self) -> None:
        """Return once an item is queued or the queue is closed."""
        while not self._items and not self.closed:
            self._ready.clear()
            await self._ready.wait()

    async def linger(self, delay: float, enough: int) -> None:
        """Wait up to ``delay`` for more items; return early once ``enough`` are queued."""
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

    def take_entries(self, max_items: int, max_bytes: int = 1 << 18) -> list[list[Any]]:
        """Up to ``max_items`` queued [key, item] entries in order, stopping once ``max_bytes``
        are taken (one item may be larger; sizes are ``len(item)``)."""
        batch: list[list[Any]] = []
        items = self._items
        by_key = self._by_key
        size = 0
        while items and len(batch) < max_items and size < max_bytes:
            entry = items.popleft()
            key = entry[0]
            if key is not None and by_key.get(key) is entry:
                del by_key[key]
            batch.append(entry)
            size += len(entry[1])
        return batch

    def take(self, max_items: int, max_bytes: int = 1 << 18) -> list[T]:
        """The items of ``take_entries``: what one frame carries."""
        return [entry[1] for entry in self.take_entries(max_items, max_bytes)]

    async def get_batch(self, max_items: int, max_bytes: int = 1 << 18) -> list[T]:
        """Wait for at least one item, then take a batch; empty once closed and drained."""
        await self.wait()
        return self.take(max_items, max_bytes)

    def requeue(self, entries: list[list[Any]]) -> None:
        """Put entries taken but not delivered back in front, in order, keys and all."""
        for entry in reversed(entries):
            self._items.appendleft(entry)
            key = entry[0]
            if key is not None and key not in self._by_key:
                self._by_key[key] = entry
        if entries and not self._ready.is_set():
            self._ready.set()

    def __aiter__(self) -> KeyedQueue[T]:
        return self

    async def __anext__(self) -> T:
        """The oldest item, waiting for one; ends once the queue is closed and drained."""
        await self.wait()
        if not self._items:
            raise StopAsyncIteration
        entry = self._items.popleft()
        self._forget(entry)
        item: T = entry[1]
        return item


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)
