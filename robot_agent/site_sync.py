"""The robot follows the live site: ``site_changed`` from the server replaces its on-board
site (the fallback planner and the touch screen's menu); ``site_loaded`` says which version it
now runs (also on every connect, so a robot that was away gets the current version)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.site import SiteLoaded
from guidebot.service import Service

__all__ = ["SiteFollower"]

log = logging.getLogger(__name__)


class SiteFollower(Service):
    def __init__(self, endpoint: Endpoint, robot: str, apply: Callable[[Any], None]) -> None:
        """``apply`` receives the validated ``Site`` of each new version."""
        super().__init__()
        self.ep = endpoint
        self.robot = robot
        self.apply = apply
        self.version = 0

    async def on_start(self) -> None:
        self.subscribe(self.ep, "site_changed", self._on_changed)

    def announce(self) -> None:
        """Tell the server which version this robot runs (0: none from the server yet)."""
        self.ep.publish(SiteLoaded(robot=self.robot, version=self.version))

    def _on_changed(self, message: Message) -> None:
        from guidebot.site.validate import SiteInvalid, validate_site

        version = int(message.payload.get("version", 0))
        if version == self.version:
            return
        data = dict(message.payload.get("site") or {})
        # The robots' view leaves the tokens out; the schema wants one per robot.
        data["robots"] = [{**r, "token": "x" * 8} for r in data.get("robots", [])]
        try:
            site = validate_site(data)
        except SiteInvalid as exc:
            log.error("%s: site version %d refused: %s", self.robot, version, exc)
            return
        self.apply(site)
        self.version = version
        log.info("%s: now on site version %d", self.robot, version)
        self.announce()
