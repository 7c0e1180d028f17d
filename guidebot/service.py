"""One life cycle for every component of every process (server, robot agent, building simulator).

A component subclasses ``Service`` and overrides ``on_start`` (and, rarely, ``on_stop``). What
it takes while starting (bus subscriptions, background tasks, other services, cleanup
callbacks) it registers here, and ``stop`` gives it back in reverse order: once, whatever
``on_start`` had reached when it failed, and however many times ``stop`` is called. So every
component starts and stops the same way (``await x.start()`` / ``await x.stop()``, or
``async with x``), and an exit stack needs one call for all of them.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable, Coroutine, Mapping
from types import TracebackType
from typing import Any, Protocol, Self, TypeVar

__all__ = ["Service", "Startable", "cancel_and_wait"]

log = logging.getLogger(__name__)

T = TypeVar("T")
M = TypeVar("M")


class Startable(Protocol):
    """Anything with the service life cycle (a ``Service``, or a class shaped like one)."""

    async def start(self) -> None: ...

    async def stop(self) -> None: ...


async def cancel_and_wait(task: asyncio.Task[Any] | None) -> None:
    """Cancel ``task`` and wait until it has really ended; a failure it ended with is logged.

    Cancelled again every half second: Python 3.11's wait_for (inside pymodbus, websockets)
    can swallow a cancellation that races with an answer.
    """
    if task is None:
        return
    while not task.done():
        task.cancel()
        await asyncio.wait([task], timeout=0.5)
    if not task.cancelled() and (error := task.exception()) is not None:
        log.error("%s ended with %r", task.get_name(), error, exc_info=error)


class Service:
    """Base of the components: subscriptions, background tasks, start, stop, ``async with``."""

    def __init__(self) -> None:
        self._cleanup = contextlib.AsyncExitStack()
        self._running = False

    # --- the life cycle ------------------------------------------------------------------
    @property
    def running(self) -> bool:
        """True between a successful ``start`` and ``stop``."""
        return self._running

    async def start(self) -> None:
        """Run ``on_start``; if it fails, give back what it took, then raise its error."""
        if self._running:
            return
        try:
            await self.on_start()
        except BaseException:
            await self._give_back()
            raise
        self._running = True

    async def stop(self) -> None:
        """``on_stop``, then everything registered, newest first. Safe to call again."""
        was_running, self._running = self._running, False
        try:
            if was_running:
                await self.on_stop()
        finally:
            await self._give_back()

    async def on_start(self) -> None:
        """Subscribe, spawn and start what the component needs (override)."""

    async def on_stop(self) -> None:
        """Work to do before the registered cleanup runs (override if needed)."""

    async def __aenter__(self) -> Self:
        await self.start()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.stop()

    async def _give_back(self) -> None:
        stack, self._cleanup = self._cleanup, contextlib.AsyncExitStack()
        await stack.aclose()

    # --- what a component takes while starting --------------------------------------------
    def subscribe(self, endpoint: Any, pattern: str, handler: Any, **options: Any) -> None:
        """``endpoint.subscribe(pattern, handler)``, unsubscribed on stop."""
        self._cleanup.callback(endpoint.subscribe(pattern, handler, **options))

    def on(
        self, endpoint: Any, model: type[M], handler: Callable[[Any, M], object], **options: Any
    ) -> None:
        """``endpoint.on(model, handler)``: ``handler(message, payload)`` gets the payload as
        ``model`` (guidebot/bus.py); unsubscribed on stop."""
        self._cleanup.callback(endpoint.on(model, handler, **options))

    def subscribe_all(self, endpoint: Any, handlers: Mapping[str, Any], **options: Any) -> None:
        """``subscribe`` for each pattern -> handler, in order."""
        for pattern, handler in handlers.items():
            self.subscribe(endpoint, pattern, handler, **options)

    def spawn(self, coro: Coroutine[Any, Any, T], name: str) -> asyncio.Task[T]:
        """A background task of this component, cancelled and awaited on stop."""
        task = asyncio.get_running_loop().create_task(coro, name=name)
        self._cleanup.push_async_callback(cancel_and_wait, task)
        return task

    def on_cleanup(self, callback: Callable[[], Any]) -> None:
        """Call ``callback`` on stop (awaited if it returns an awaitable)."""

        async def call() -> None:
            result = callback()
            if isinstance(result, Awaitable):
                await result

        self._cleanup.push_async_callback(call)

    async def enter(self, service: Startable) -> None:
        """Start another component now and stop it on stop (before what came earlier)."""
        await service.start()
        self._cleanup.push_async_callback(service.stop)
