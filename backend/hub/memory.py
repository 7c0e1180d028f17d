"""Keep the cyclic garbage collector's full passes short on a hub with many clients.

Measured on the 2-core VM (docs/protocol.md, "Measured"): a server with 1000 WebSocket clients
holds about 290 000 objects the collector tracks (120 000 from imports and start-up, about 170
per connection). A full collection walks all of them: 200-300 ms of CPU, 700 ms of wall time on
a busy machine, during which no frame is read or sent. Those objects live as long as their
connection, so scanning them again and again finds nothing.

``GcFreezer`` moves them to the collector's permanent generation (``gc.freeze()``) shortly after
clients connect; full passes then only walk what is young, a few tens of milliseconds. Reference
counting still frees frozen objects as usual. What freezing costs: reference cycles left behind by
closed connections are not reclaimed while frozen. So once enough clients have gone (a quarter of
those connected, at least ``min_churn``) everything is unfrozen and collected once, and when the
hub stops it unfreezes everything (so tests that start many servers in one process keep nothing).

Neither happens while the collector is off (``gc.isenabled()`` false): site work pauses it
(backend/site/offloop.py) and freezes what it built when it ends, and an explicit collection
meanwhile would walk every object that work has allocated so far, on the event loop (97 ms
measured: 20 robots connecting just before a 10 000-node site was published). A freeze due then
is tried again ``delay`` later; a reclaim waits for the next client to leave.
"""

from __future__ import annotations

import asyncio
import gc
import logging

__all__ = ["GcFreezer"]

log = logging.getLogger(__name__)


class GcFreezer:
    """Freeze long-lived objects after clients connect; reclaim after clients leave."""

    def __init__(
        self,
        *,
        enabled: bool = True,
        delay: float = 1.0,
        min_churn: int = 64,
        churn_ratio: float = 0.25,
    ) -> None:
        self.enabled = enabled
        self.delay = delay
        self.min_churn = min_churn
        self.churn_ratio = churn_ratio
        self.freezes = 0
        self.reclaims = 0
        self._timer: asyncio.TimerHandle | None = None
        self._gone = 0
        self._frozen = False

    def attached(self, connected: int) -> None:
        """A client connected: freeze in ``delay`` seconds (one freeze per connection burst)."""
        if not self.enabled or self._timer is not None:
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # no event loop (unit tests drive the hub directly)
            return
        self._timer = loop.call_later(self.delay, self._freeze)

    def detached(self, connected: int) -> None:
        """A client left: after enough of them, unfreeze and collect once."""
        if not self._frozen:
            return
        self._gone += 1
        if gc.isenabled() and self._gone >= max(
            self.min_churn, self.churn_ratio * (connected + self._gone)
        ):
            self._gone = 0
            self._frozen = False
            self.reclaims += 1
            gc.unfreeze()
            collected = gc.collect()
            log.info("hub: %d clients left: unfroze and collected %d objects", connected, collected)

    def _freeze(self) -> None:
        if not gc.isenabled():  # paused by site work: see the module's docstring
            self._timer = asyncio.get_running_loop().call_later(self.delay, self._freeze)
            return
        self._timer = None
        gc.collect(1)  # young garbage is not frozen along with the live objects
        gc.freeze()
        self._frozen = True
        self.freezes += 1
        # Not gc.get_freeze_count(): it walks every frozen object (45-110 ms with a large site).
        log.debug("hub: long-lived objects frozen (freeze %d)", self.freezes)

    def stop(self) -> None:
        """The hub stops: cancel the pending freeze and give everything back to the collector."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._frozen:
            self._frozen = False
            gc.unfreeze()
