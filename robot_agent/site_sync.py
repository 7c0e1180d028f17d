"""The robot follows the live site: ``site_changed`` from the server replaces its on-board
site (the fallback planner and the touch screen's menu); ``site_loaded`` says which version it
now runs (also on every connect, so a robot that was away gets the current version).

Validating a site and building its route graph takes from milliseconds (the demo museum) to
seconds (a 10 000-node site), and the first one imports SciPy (about 0.3 s): done on the
robot's event loop it would stall the loop that feeds RoboCAN's 350 ms watchdogs. So a new
version is read in a thread, one at a time, and only the result is applied on the loop; a
version that arrives meanwhile waits, and of several waiting only the newest is read.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.site import SiteLoaded
from guidebot.service import Service

__all__ = ["SiteFollower"]

log = logging.getLogger(__name__)


def _read_site(payload: dict[str, Any]) -> Any:
    """The validated ``Site`` of a site_changed payload (raises SiteInvalid)."""
    from guidebot.site.validate import validate_site

    data = dict(payload.get("site") or {})
    # The robots' view leaves the tokens out; the schema wants one per robot.
    data["robots"] = [{**r, "token": "x" * 8} for r in data.get("robots", [])]
    return validate_site(data)


class SiteFollower(Service):
    def __init__(
        self,
        endpoint: Endpoint,
        robot: str,
        apply: Callable[[Any], None],
        prepare: Callable[[Any], Any] = lambda site: site,
    ) -> None:
        """``prepare`` receives the validated ``Site`` of each new version, in a thread;
        ``apply`` receives what it returns, on the event loop."""
        super().__init__()
        self.ep = endpoint
        self.robot = robot
        self.apply = apply
        self.prepare = prepare
        self.version = 0
        self._waiting: Message | None = None
        self._arrived = asyncio.Event()

    async def on_start(self) -> None:
        self.subscribe(self.ep, "site_changed", self._on_changed)
        self.spawn(self._follow(), name=f"{self.robot}-site")

    def announce(self) -> None:
        """Tell the server which version this robot runs (0: none from the server yet)."""
        self.ep.publish(SiteLoaded(robot=self.robot, version=self.version))

    def _on_changed(self, message: Message) -> None:
        self._waiting = message  # replaces one that was waiting: the newest is read next
        self._arrived.set()

    async def _follow(self) -> None:
        from guidebot.site.validate import SiteInvalid

        while True:
            await self._arrived.wait()
            self._arrived.clear()
            message, self._waiting = self._waiting, None
            if message is None:
                continue
            version = int(message.payload.get("version", 0))
            if version == self.version:
                continue
            try:
                prepared = await asyncio.to_thread(self._read, message.payload)
            except SiteInvalid as exc:
                log.error("%s: site version %d refused: %s", self.robot, version, exc)
                continue
            except Exception:
                log.exception("%s: site version %d could not be read", self.robot, version)
                continue
            self.apply(prepared)
            self.version = version
            log.info("%s: now on site version %d", self.robot, version)
            self.announce()

    def _read(self, payload: dict[str, Any]) -> Any:
        return self.prepare(_read_site(payload))
