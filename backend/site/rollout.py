"""A published site reaching the robots: ``site_changed`` out, ``site_loaded`` back, timed.

Each version is sent once to every robot (broadcast); a robot that connects later says which
version it runs (``site_loaded`` on connect) and gets the current one if it is behind. Staff
pages see ``site_rollout``: which of the robots connected at publish time run the new version
and how many milliseconds each took.

The site in the payload is JSON already (an ``orjson.Fragment``), written in a thread in short
calls (``jsonio.dumps_bytes``): the hub copies it into each message it encodes, where writing
a 10 000-node site (2.4 MB) took one 6-25 ms native call on the event loop, once per broadcast
and again for each robot that was behind. In-process subscribers of ``site_changed`` get the
fragment, not a dict: the robots read it from the wire.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import orjson

from backend.site.offloop import off_loop, release
from backend.site.service import SiteService
from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.site import SitePublished, SiteRollout
from guidebot.service import Service
from guidebot.site import jsonio
from guidebot.site.bulk import dump_site_doc
from guidebot.site.dispose import dispose
from guidebot.site.schema import Site

__all__ = ["RolloutTracker", "robot_view"]


def robot_view(site: Site) -> dict[str, Any]:
    """The site as robots get it: without the robots' token digests."""
    data = dump_site_doc(site)
    data["robots"] = [{k: v for k, v in r.items() if k != "token"} for r in data["robots"]]
    return data


class RolloutTracker(Service):
    def __init__(
        self,
        endpoint: Endpoint,
        sites: SiteService,
        connected_robots: Callable[[], set[str]],
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.sites = sites
        self.connected_robots = connected_robots
        self.version = 0
        self.expected: list[str] = []
        self.loaded_ms: dict[str, float] = {}
        self.ms: float | None = None
        self._t0 = 0.0
        self._payload: dict[str, Any] = {}

    async def on_start(self) -> None:
        self._payload = await off_loop(self._make_payload, self.sites.site)
        self.version = self.sites.version
        self.subscribe(self.ep, "site_loaded", self._on_loaded)

    def _make_payload(self, site: Site) -> dict[str, Any]:
        """The payload of site_changed, the site written as JSON (call it in a thread)."""
        view = [robot_view(site)]
        encoded = jsonio.dumps_bytes(view[0])
        dispose(view)  # the dict of a large site, freed a piece at a time
        return {
            "version": self.sites.version,
            "published_by": self.sites.published_by,
            "site": orjson.Fragment(encoded),
        }

    async def on_site(self, site: Site) -> None:
        """SiteService listener: send the new version to every robot and start the clock."""
        self._t0 = time.perf_counter()
        payload = await off_loop(self._make_payload, site)
        known = {r.name for r in site.robots}
        self.version = self.sites.version
        self.expected = sorted(self.connected_robots() & known)
        self.loaded_ms = {}
        self.ms = None
        retired = [self._payload]  # the previous document, freed in a thread
        self._payload = payload
        self.ep.publish("site_changed", self._payload)
        self.ep.publish(SitePublished(version=self.version))  # the visitor pages' menus
        self._report()
        await release(retired)

    def _on_loaded(self, message: Message) -> None:
        robot = message.source
        version = int(message.payload.get("version", 0))
        if version != self.version:
            # A robot behind (it just connected, or missed the broadcast): send it the current.
            self.ep.publish("site_changed", self._payload, destination=robot)
            return
        if robot in self.expected and robot not in self.loaded_ms:
            self.loaded_ms[robot] = round((time.perf_counter() - self._t0) * 1000, 2)
            if len(self.loaded_ms) == len(self.expected):
                self.ms = max(self.loaded_ms.values())
            self._report()

    def status(self) -> SiteRollout:
        return SiteRollout(
            version=self.version,
            expected=self.expected,
            loaded_ms=self.loaded_ms,
            complete=set(self.loaded_ms) == set(self.expected),
            ms=self.ms if self.expected else 0.0,
        )

    def _report(self) -> None:
        self.ep.publish(self.status())
