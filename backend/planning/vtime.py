"""Virtual time for one process: an asyncio event loop whose clock jumps to its next timer
whenever nothing is ready, so a whole system (server, robots, building) that only waits on
timers and sockets runs as fast as the CPU allows and in exact simulated seconds.

While ``virtual_time()`` is active, ``time.time()`` and ``time.monotonic()`` read the virtual
clock (every module of the product reads time through the ``time`` module's attributes), so
timestamps in the event log, robot clocks, lock timers and the loop's timers agree. A module
that keeps a reference to them (a default argument ``clock=time.time``, a dataclass's
``default_factory=time.time``) took it when it was imported: the run's process calls
``install()`` before it imports any of the product, so those references are this module's
switches, which read the virtual clock while a run is active. Without it a door's trouble
closure (the closures service's ``clock=time.time``) ran on the real clock: held 120 real
seconds, it stayed closed for hours of a virtual day.

Work in threads (aiosqlite's connection thread, its connecting included, ``run_in_executor``,
anyio's worker threads behind Starlette's thread pool) is counted: while any is pending, the
loop waits on the real clock and does not advance the virtual one, so a database write takes
no simulated time. Data written to a loopback socket is readable by the peer when the write
returns, so the loop sees it before it jumps. docs/planning.md, "The virtual run"."""

from __future__ import annotations

import asyncio
import contextlib
import selectors
import threading
import time
from collections.abc import Awaitable, Callable, Iterator
from typing import Any, TypeVar

__all__ = ["VirtualClock", "VirtualLoop", "install", "installed", "virtual_time"]

T = TypeVar("T")

REAL_WAIT_S = 0.05
"""Real seconds the loop waits at a time for a thread's result (virtual time stands still)."""


_REAL_TIME, _REAL_MONOTONIC = time.time, time.monotonic
_active: VirtualClock | None = None
"""The running virtual clock (None: the real clock)."""


def _time() -> float:
    clock = _active
    return _REAL_TIME() if clock is None else clock.time()


def _monotonic() -> float:
    clock = _active
    return _REAL_MONOTONIC() if clock is None else clock.monotonic()


def install() -> None:
    """Make ``time.time`` and ``time.monotonic`` this module's switches for good (the real
    clock, the virtual one while ``virtual_time`` runs), so that references modules take
    when they are imported follow a run's clock too: call it before importing the product."""
    time.time, time.monotonic = _time, _monotonic  # type: ignore[assignment]


def installed() -> bool:
    """``install()`` was called (and nobody replaced the switches since)."""
    return time.time is _time and time.monotonic is _monotonic  # type: ignore[comparison-overlap]


class VirtualClock:
    """Monotonic seconds since the start (``monotonic``) and epoch seconds (``time``)."""

    def __init__(self, epoch: float) -> None:
        self.epoch = epoch
        self.now = 0.0
        self.threads = 0
        self._lock = threading.Lock()

    def monotonic(self) -> float:
        return self.now

    def time(self) -> float:
        return self.epoch + self.now

    def busy(self, delta: int) -> None:
        with self._lock:
            self.threads += delta


class _Selector(selectors.BaseSelector):
    """The loop's selector: ready I/O first; then, if threads work, a real wait; else the jump."""

    def __init__(self, clock: VirtualClock) -> None:
        self.inner = selectors.DefaultSelector()
        self.clock = clock

    def register(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self.inner.register(fileobj, events, data)

    def unregister(self, fileobj: Any) -> selectors.SelectorKey:
        return self.inner.unregister(fileobj)

    def modify(self, fileobj: Any, events: int, data: Any = None) -> selectors.SelectorKey:
        return self.inner.modify(fileobj, events, data)

    def get_map(self) -> Any:
        return self.inner.get_map()

    def close(self) -> None:
        self.inner.close()

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        ready = self.inner.select(0)
        if ready or timeout == 0:
            return ready
        if self.clock.threads > 0:
            return self.inner.select(REAL_WAIT_S)
        if timeout is None:
            # Nothing scheduled and nobody working: only the outside world can wake us.
            return self.inner.select(REAL_WAIT_S)
        self.clock.now += max(0.0, timeout)
        return []


class VirtualLoop(asyncio.SelectorEventLoop):
    """A selector event loop on a VirtualClock."""

    def __init__(self, clock: VirtualClock) -> None:
        super().__init__(_Selector(clock))
        self.clock = clock

    def time(self) -> float:
        return self.clock.now

    def run_in_executor(self, executor: Any, func: Any, *args: Any) -> Any:  # type: ignore[override]
        future = super().run_in_executor(executor, func, *args)
        self.clock.busy(1)
        future.add_done_callback(lambda _: self.clock.busy(-1))
        return future


async def _counted(clock: VirtualClock, awaitable: Awaitable[T]) -> T:
    clock.busy(1)
    try:
        return await awaitable
    finally:
        clock.busy(-1)


@contextlib.contextmanager
def _patched(clock: VirtualClock) -> Iterator[None]:
    """time.time/time.monotonic on the virtual clock; aiosqlite's and anyio's threads counted."""
    import aiosqlite.core
    import anyio.to_thread

    saved_time, saved_mono = time.time, time.monotonic
    saved_exec: Any = aiosqlite.core.Connection._execute  # untyped (mypy strict)
    saved_connect = aiosqlite.core.Connection._connect
    saved_run_sync = anyio.to_thread.run_sync

    async def execute(self: Any, fn: Any, *args: Any, **kwargs: Any) -> Any:
        return await _counted(clock, saved_exec(self, fn, *args, **kwargs))

    async def connect(self: Any) -> Any:
        return await _counted(clock, saved_connect(self))

    async def run_sync(func: Callable[..., T], *args: Any, **kwargs: Any) -> T:
        return await _counted(clock, saved_run_sync(func, *args, **kwargs))

    global _active
    saved_active, _active = _active, clock
    time.time, time.monotonic = clock.time, clock.monotonic  # type: ignore[assignment]
    aiosqlite.core.Connection._execute = execute  # type: ignore[method-assign]
    aiosqlite.core.Connection._connect = connect  # type: ignore[method-assign]
    anyio.to_thread.run_sync = run_sync  # type: ignore[assignment]
    try:
        yield
    finally:
        _active = saved_active
        time.time, time.monotonic = saved_time, saved_mono  # type: ignore[assignment]
        aiosqlite.core.Connection._execute = saved_exec  # type: ignore[method-assign]
        aiosqlite.core.Connection._connect = saved_connect  # type: ignore[method-assign]
        anyio.to_thread.run_sync = saved_run_sync  # type: ignore[assignment]


def virtual_time(main: Awaitable[T], *, epoch: float | None = None) -> T:
    """Run ``main`` to the end on a new VirtualLoop (this thread must have no running loop)."""
    clock = VirtualClock(time.time() if epoch is None else epoch)
    loop = VirtualLoop(clock)
    with _patched(clock):
        try:
            asyncio.set_event_loop(loop)
            return loop.run_until_complete(main)
        finally:
            with contextlib.suppress(Exception):
                loop.run_until_complete(loop.shutdown_asyncgens())
                loop.run_until_complete(loop.shutdown_default_executor())
            asyncio.set_event_loop(None)
            loop.close()
