"""Keep the cyclic garbage collector's full passes short on a hub with many clients.

Measured on the 2-core VM (docs/protocol.md, "Measured"): a server with 1000 WebSocket clients
holds about 290 000 objects the collector tracks (120 000 from imports and start-up, about 170
per connection). A full collection walks all of them: 200-300 ms of CPU, 700 ms of wall time on
a busy machine, during which no frame is read or sent. Those objects live as long as their
connection, so scanning them again and again finds nothing.

``GcFreezer`` moves them to the collector's permanent generation (``gc.freeze()``) shortly after
clients connect; full passes then only walk what is young, a few tens of milliseconds. Reference
counting still frees frozen objects as usual; only a reference cycle among frozen objects stays
until they are unfrozen, and CPython (3.11) cannot collect a part of the permanent generation:
a pass over it walks everything frozen, the site included (0.9-1.3 s with a 10 000-node site on
this VM). So no such pass runs while the hub serves; what would need one is not made:
- a closed connection left one cycle on asyncio's own event loop: its socket transport keeps
  its read callback, a bound method of itself (CPython 3.11's selector_events), so the
  transport, its socket and their dicts (5 objects) waited for a full pass.
  ``break_transport_cycles`` drops that callback once the connection is lost: reference
  counting frees the transport even when frozen. Under uvloop (uvicorn's loop when installed,
  as in production) and on the hub's own listener (picows) no cycle is left at all (measured:
  tests/hub/test_memory.py);
- after enough clients have left (a quarter of those connected, at least ``min_churn``) a
  *reclaim* runs: one collection of what is not frozen (``gc.collect(2)``, the young cycles of
  their departures, an exception's traceback say), then a freeze of what survived. It walks
  only what was allocated since the last freeze, never the frozen site;
- a freeze collects what is not frozen yet before it freezes (start-up's objects the first
  time, 100 ms measured; then what came since, 2.5 ms after 100 robots connected), so garbage
  is not frozen with the live objects. What can still be: the HTTP protocol of a WebSocket
  handshake that a freeze catches half-way (uvicorn's, a cycle with its parser), garbage once
  the handshake ends; it waits until the hub stops.
The reclaim still runs off the hot path and spaced: never inside a client's leave (that is a
reconnect storm's hot path) but on its own timer once no client has come or gone for
``quiet_s`` (at the latest ``max_wait_s`` after it fell due), at most once per
``min_interval_s`` and at least 1/``max_duty`` times its own duration apart; never while the
collector is off (``gc.isenabled()`` false): site work pauses it (backend/site/offloop.py) and
freezes what it built when it ends, and an explicit collection meanwhile would walk every object
that work has allocated so far, on the event loop (97 ms measured: 20 robots connecting just
before a 10 000-node site was published). A freeze or a reclaim due then is tried again
``delay`` later. When the hub stops it unfreezes everything (so tests that start many servers
in one process keep nothing).
"""

from __future__ import annotations

import asyncio
import asyncio.selector_events
import gc
import logging
import time
from collections.abc import Callable
from typing import Any

__all__ = ["GcFreezer", "break_transport_cycles"]

log = logging.getLogger(__name__)


def break_transport_cycles() -> None:
    """Make asyncio's socket transports drop their read callback (a bound method of the
    transport itself: a reference cycle) once their connection is lost, so a closed connection
    is freed by reference counting, frozen or not. Idempotent; a Python without that attribute
    is left alone."""
    transport: Any = getattr(asyncio.selector_events, "_SelectorTransport", None)
    lost = getattr(transport, "_call_connection_lost", None)
    if lost is None or getattr(lost, "breaks_cycle", False):
        return

    def call_connection_lost(self: Any, exc: BaseException | None) -> None:
        try:
            lost(self, exc)
        finally:
            if "_read_ready_cb" in self.__dict__:
                self._read_ready_cb = None  # as __init__ leaves it

    call_connection_lost.breaks_cycle = True  # type: ignore[attr-defined]
    transport._call_connection_lost = call_connection_lost


class GcFreezer:
    """Freeze long-lived objects after clients connect; after clients leave, collect what is
    not frozen, off the hot path."""

    def __init__(
        self,
        *,
        enabled: bool = True,
        delay: float = 1.0,
        min_churn: int = 64,
        churn_ratio: float = 0.25,
        quiet_s: float = 5.0,
        max_wait_s: float = 60.0,
        min_interval_s: float = 300.0,
        max_duty: float = 0.001,
        clock: Callable[[], float] = time.monotonic,
        stopwatch: Callable[[], float] = time.perf_counter,
    ) -> None:
        """``clock`` decides when a reclaim may run, ``stopwatch`` times it (tests pass their
        own)."""
        self.enabled = enabled
        if enabled:
            break_transport_cycles()
        self.delay = delay
        self.min_churn = min_churn
        self.churn_ratio = churn_ratio
        self.quiet_s = quiet_s
        self.max_wait_s = max_wait_s
        self.min_interval_s = min_interval_s
        self.max_duty = max_duty
        self.clock = clock
        self.stopwatch = stopwatch
        self.freezes = 0
        self.reclaims = 0
        self.last_reclaim_s = 0.0
        """How long the last reclaim's collection held the loop."""
        self.last_freeze_s = 0.0
        """How long the last freeze (its collection) held the loop."""
        self.last_reclaimed = 0
        """Objects the last reclaim found unreachable."""
        self._timer: asyncio.TimerHandle | None = None
        self._reclaim_timer: asyncio.TimerHandle | None = None
        self._gone = 0
        self._frozen = False
        self._due_since: float | None = None
        """When enough clients had left for a reclaim (None: none due)."""
        self._last_change = 0.0
        self._next_allowed = 0.0
        """No reclaim before this (min_interval_s and max_duty after the last one)."""

    def attached(self, connected: int) -> None:
        """A client connected: freeze in ``delay`` seconds (one freeze per connection burst)."""
        self._last_change = self.clock()
        if not self.enabled or self._timer is not None:
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # no event loop (unit tests drive the hub directly)
            return
        self._timer = loop.call_later(self.delay, self._freeze)

    def detached(self, connected: int) -> None:
        """A client left: after enough of them, a reclaim is due (run later, not here)."""
        self._last_change = self.clock()
        if not self._frozen or self._due_since is not None:
            return
        self._gone += 1
        if self._gone >= max(self.min_churn, self.churn_ratio * (connected + self._gone)):
            self._gone = 0
            self._due_since = self._last_change
            self._schedule_reclaim(self.quiet_s)

    @property
    def reclaim_due(self) -> bool:
        return self._due_since is not None

    def _schedule_reclaim(self, after: float) -> None:
        if self._reclaim_timer is not None:
            self._reclaim_timer.cancel()
            self._reclaim_timer = None
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:
            return
        self._reclaim_timer = loop.call_later(max(after, 0.0), self._reclaim)

    def _reclaim(self) -> None:
        """Run the due reclaim if the hub is quiet, the spacing allows and the collector is on;
        else look again when it could."""
        self._reclaim_timer = None
        if self._due_since is None or not self._frozen:
            self._due_since = None
            return
        now = self.clock()
        wait = max(
            self._next_allowed - now,
            min(self._last_change + self.quiet_s, self._due_since + self.max_wait_s) - now,
        )
        if not gc.isenabled():  # paused by site work: see the module's docstring
            wait = max(wait, self.delay)
        if wait > 0:
            self._schedule_reclaim(wait)
            return
        self._due_since = None
        self.reclaims += 1
        started = self.stopwatch()
        self.last_reclaimed = collected = gc.collect(2)  # the frozen are not walked
        gc.freeze()  # what survived is long-lived: later full passes stay short
        self.last_reclaim_s = took = self.stopwatch() - started
        self._next_allowed = self.clock() + max(self.min_interval_s, took / self.max_duty)
        log.info(
            "hub: reclaim after clients left: collected %d objects in %.0f ms; next not before"
            " %.0f s",
            collected,
            took * 1000,
            self._next_allowed - self.clock(),
        )

    def _freeze(self) -> None:
        if not gc.isenabled():  # paused by site work: see the module's docstring
            self._timer = asyncio.get_running_loop().call_later(self.delay, self._freeze)
            return
        self._timer = None
        started = self.stopwatch()
        # Garbage is not frozen along with the live objects: the young, and what connections
        # just made left (uvicorn's HTTP protocol of a WebSocket upgrade). Only what is not
        # frozen yet is walked: the first time start-up's objects, then what came since.
        gc.collect(2)
        gc.freeze()
        self.last_freeze_s = self.stopwatch() - started
        self._frozen = True
        self.freezes += 1
        # Not gc.get_freeze_count(): it walks every frozen object (45-110 ms with a large site).
        log.debug("hub: long-lived objects frozen (freeze %d)", self.freezes)

    def stop(self) -> None:
        """The hub stops: cancel the pending freeze and reclaim and give everything back to
        the collector."""
        for timer in (self._timer, self._reclaim_timer):
            if timer is not None:
                timer.cancel()
        self._timer = self._reclaim_timer = None
        self._due_since = None
        if self._frozen:
            self._frozen = False
            gc.unfreeze()
