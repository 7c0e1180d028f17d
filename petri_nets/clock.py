"""Clocks for the engine: real asyncio time with a time-scale factor, or virtual time.

Timers are the only place the engine meets time, so tests and ``guidebot petri run`` use the
virtual clock (time advances only when told, nothing sleeps) and demos run K times faster.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
from collections.abc import Callable
from typing import Protocol

__all__ = ["AsyncioClock", "Clock", "TimerHandle", "VirtualClock"]


class TimerHandle(Protocol):
    def cancel(self) -> None: ...


class Clock(Protocol):
    """What the engine needs from time."""

    def now(self) -> float:
        """Seconds of task time (scaled), monotonic."""
        ...

    def call_later(self, delay: float, callback: Callable[[], None]) -> TimerHandle: ...

    def call_soon(self, callback: Callable[[], None]) -> TimerHandle: ...


class AsyncioClock:
    """The running event loop's clock; ``scale`` K > 1 makes timers run K times faster."""

    def __init__(self, scale: float = 1.0, loop: asyncio.AbstractEventLoop | None = None) -> None:
        if scale <= 0:
            raise ValueError(f"time scale must be positive, got {scale}")
        self.scale = scale
        self._loop = loop

    @property
    def loop(self) -> asyncio.AbstractEventLoop:
        if self._loop is None:
            self._loop = asyncio.get_running_loop()
        return self._loop

    def now(self) -> float:
        return self.loop.time() * self.scale

    def call_later(self, delay: float, callback: Callable[[], None]) -> TimerHandle:
        return self.loop.call_later(max(0.0, delay) / self.scale, callback)

    def call_soon(self, callback: Callable[[], None]) -> TimerHandle:
        return self.loop.call_soon(callback)


class _VirtualHandle:
    __slots__ = ("callback", "cancelled", "when")

    def __init__(self, when: float, callback: Callable[[], None]) -> None:
        self.when = when
        self.callback = callback
        self.cancelled = False

    def cancel(self) -> None:
        self.cancelled = True


class VirtualClock:
    """Time that moves only in ``advance``/``run``: deterministic tests, instant dry runs."""

    def __init__(self, start: float = 0.0) -> None:
        self._now = start
        self._queue: list[tuple[float, int, _VirtualHandle]] = []
        self._seq = itertools.count()

    def now(self) -> float:
        return self._now

    def call_later(self, delay: float, callback: Callable[[], None]) -> _VirtualHandle:
        handle = _VirtualHandle(self._now + max(0.0, delay), callback)
        heapq.heappush(self._queue, (handle.when, next(self._seq), handle))
        return handle

    def call_soon(self, callback: Callable[[], None]) -> _VirtualHandle:
        return self.call_later(0.0, callback)

    def pending(self) -> int:
        return sum(1 for _, _, h in self._queue if not h.cancelled)

    def next_time(self) -> float | None:
        while self._queue and self._queue[0][2].cancelled:
            heapq.heappop(self._queue)
        return self._queue[0][0] if self._queue else None

    def advance(self, seconds: float) -> None:
        """Move time forward by ``seconds``, running every callback due on the way, in order."""
        self.run(until=self._now + seconds)

    def run_ready(self) -> int:
        """Run the callbacks already due now (not those they schedule): one loop iteration."""
        last = next(self._seq)
        ran = 0
        while self._queue and self._queue[0][0] <= self._now and self._queue[0][1] < last:
            _, _, handle = heapq.heappop(self._queue)
            if not handle.cancelled:
                handle.callback()
                ran += 1
        return ran

    def run(
        self,
        until: float | None = None,
        stop: Callable[[], bool] | None = None,
        max_callbacks: int | None = None,
    ) -> None:
        """Run callbacks in time order until none is left, ``until`` is passed, ``stop()`` or
        ``max_callbacks`` ran (a net that reschedules itself at once would never let time pass).
        """
        budget = max_callbacks
        while True:
            if stop is not None and stop():
                return
            if budget is not None:
                if budget <= 0:
                    return
                budget -= 1
            when = self.next_time()
            if when is None or (until is not None and when > until):
                break
            _, _, handle = heapq.heappop(self._queue)
            self._now = max(self._now, handle.when)
            handle.callback()
        if until is not None:
            self._now = max(self._now, until)
