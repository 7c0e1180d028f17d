"""Publishing a net: checked by the engine's rules against the library it joins, stored, put
in the server's dispatch, sent to every robot (``nets_changed``; ``nets_loaded`` back).

A robot that connects says which library version it runs (``nets_loaded`` on connect) and
gets the current one if it is behind, as the site's rollout does (backend/site/rollout.py).
Running instances are not touched anywhere: the next start of a net takes its new version.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from backend.net_library.store import NetStore, NetVersion
from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.nets import NetsChanged, NetsLoaded
from guidebot.service import Service
from petri_nets.library import NetLibrary

__all__ = ["NetPublisher", "NetRefused"]

log = logging.getLogger(__name__)


class NetRefused(ValueError):
    """The net would not run, or would break a net of the library that uses it."""

    def __init__(self, problems: list[str]) -> None:
        super().__init__("; ".join(problems))
        self.problems = problems


class NetPublisher(Service):
    def __init__(self, endpoint: Endpoint, store: NetStore, library: NetLibrary) -> None:
        super().__init__()
        self.ep = endpoint
        self.store = store
        self.library = library
        self.version = 0
        """The library's publication count (0: nothing published yet)."""
        self.live: dict[str, NetVersion] = {}
        self.published_by = ""
        self.robots: dict[str, int] = {}
        """Robot -> the library version it said it runs."""
        self._lock = asyncio.Lock()

    async def on_start(self) -> None:
        self.version, self.live = await self.store.live()
        if self.live:
            problems = self.library.install({n: v.pnml for n, v in self.live.items()})
            for problem in problems:  # a stored net the engine no longer takes: say so
                log.error("published nets not installed: %s", problem)
        self.on(self.ep, NetsLoaded, self._on_loaded)

    async def publish(self, net: str, pnml: str, *, by: str, note: str = "") -> NetVersion:
        """Check, store and send ``pnml`` as ``net``'s next version; NetRefused when the
        engine refuses it (nothing is stored then)."""
        async with self._lock:
            problems = self.library.install({net: pnml})
            if problems:
                raise NetRefused([str(p) for p in problems])
            saved = await self.store.save(net, pnml, by=by, note=note)
            self.live[net] = saved
            self.version, self.published_by = saved.seq, by
            self.ep.publish(self._changed())
            log.info("net %s version %d published by %s", net, saved.version, by or "?")
            return saved

    def _changed(self) -> NetsChanged:
        return NetsChanged(
            version=self.version,
            published_by=self.published_by,
            nets={name: v.pnml for name, v in self.live.items()},
        )

    def _on_loaded(self, message: Message, loaded: NetsLoaded) -> None:
        robot = message.source
        if loaded.problems:
            log.error("%s refused nets version %d: %s", robot, loaded.version, loaded.problems)
        self.robots[robot] = loaded.version
        if loaded.version != self.version and not loaded.problems and self.version:
            self.ep.publish(self._changed(), destination=robot)

    def status(self) -> dict[str, Any]:
        """The library's version and which version each robot that answered runs."""
        return {"version": self.version, "robots": dict(sorted(self.robots.items()))}
