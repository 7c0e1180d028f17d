"""The live site: one current version, edited while the server runs (no restart).

An accepted edit is validated as a whole, stored (new version), then handed to every listener
(Task Manager, Traffic Manager, robot tokens) in order. Validation and the stored document's
dump run off the event loop (backend/site/offloop.py): a 10 000-node site takes a few hundred
milliseconds of them, which the loop would otherwise wait for. The replaced site and the stored
document are freed off the loop too (``release``): freeing them there took 10-20 ms at once.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import Any, Protocol

from backend.site.offloop import gc_paused, off_loop, release
from guidebot.site.bulk import dump_site_doc
from guidebot.site.schema import Site
from guidebot.site.validate import validate_site

__all__ = ["EMPTY_SITE", "SiteService", "SiteStore"]

EMPTY_SITE: dict[str, Any] = {
    "name": "Unconfigured site",
    "floors": [{"id": "F0", "name": "Ground floor"}],
    "nodes": [{"id": "origin", "floor": "F0", "x": 0, "y": 0}],
}

Listener = Callable[[Site], Awaitable[None] | None]
"""Called with each new site; an async listener (one that builds its tables off the event loop)
is awaited before the next listener runs and before the edit returns."""


class SiteStore(Protocol):
    async def save_site(self, data: dict[str, Any], *, by: str = "", note: str = "") -> int: ...


class SiteService:
    def __init__(self, site: Site, version: int, store: SiteStore | None = None) -> None:
        self.site = site
        self.version = version
        self.store = store
        self.published_by = ""
        self.published_at = 0.0
        self._listeners: list[Listener] = []
        self._lock = asyncio.Lock()

    def on_change(self, listener: Listener) -> None:
        self._listeners.append(listener)

    async def replace(self, data: dict[str, Any] | Site, *, by: str = "", note: str = "") -> Site:
        """Validate (raises SiteInvalid with every problem), store (a new kept version), apply."""
        site = data if isinstance(data, Site) else await self.validate(data)
        async with self._lock:
            return await self._apply(site, by=by, note=note)

    @staticmethod
    async def validate(data: dict[str, Any]) -> Site:
        """validate_site off the event loop (raises SiteInvalid with every problem)."""
        return await off_loop(validate_site, data)

    async def edit(self, change: Callable[[dict[str, Any]], Awaitable[None] | None]) -> Site:
        """Apply ``change`` to a copy of the current document, then replace it as a whole.

        Edits are serialised: two concurrent edits both land, neither overwrites the other."""
        async with self._lock:
            doc = await off_loop(dump_site_doc, self.site)
            result = change(doc)
            if result is not None:
                await result
            return await self._apply(await self.validate(doc))

    async def _apply(self, site: Site, *, by: str = "", note: str = "") -> Site:
        """Store and hand to the listeners; the caller holds the lock. The collector stays
        paused until every listener has its tables (they build in threads, see offloop). The
        stored document and the replaced site are freed in a thread (``release``)."""
        retired: list[Any] = []
        with gc_paused():
            if self.store is not None:
                retired.append(await off_loop(dump_site_doc, site))
                self.version = await self.store.save_site(retired[-1], by=by, note=note)
            else:
                self.version += 1
            retired.append(self.site)
            self.site = site
            self.published_by = by
            self.published_at = time.time()
            for listener in self._listeners:
                result = listener(site)
                if result is not None:
                    await result
            await release(retired)
        return site
