"""The robot follows the published nets: ``nets_changed`` from the server installs the nets
published from the RoboGraph editor in the robot's library; ``nets_loaded`` says which library
version it now starts nets from (also on every connect, so a robot that was away catches up).

Running instances keep the net they started with (the dispatch holds it); the next start takes
the new version. Reading and validating the nets is done in a thread (the loop feeds RoboCAN's
watchdogs), installing them on the loop. A version the robot's engine refuses is not installed
and the refusal is said in ``nets_loaded`` (the server logs it).
"""

from __future__ import annotations

import asyncio
import logging
from typing import TYPE_CHECKING

from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.nets import NetsChanged, NetsLoaded
from guidebot.service import Service

if TYPE_CHECKING:  # the agent runs without RoboGraph too (robot_agent/agent.py)
    from petri_nets.library import NetLibrary

__all__ = ["NetFollower"]

log = logging.getLogger(__name__)


class NetFollower(Service):
    def __init__(self, endpoint: Endpoint, robot: str, library: NetLibrary) -> None:
        super().__init__()
        self.ep = endpoint
        self.robot = robot
        self.library = library
        self.version = 0
        self._waiting: NetsChanged | None = None
        self._arrived = asyncio.Event()

    async def on_start(self) -> None:
        self.subscribe(self.ep, "nets_changed", self._on_changed)
        self.spawn(self._follow(), name=f"{self.robot}-nets")

    def announce(self, problems: list[str] | None = None, version: int | None = None) -> None:
        """Tell the server which library version this robot starts nets from."""
        self.ep.publish(
            NetsLoaded(
                robot=self.robot,
                version=self.version if version is None else version,
                problems=problems or [],
            )
        )

    def _on_changed(self, message: Message) -> None:
        self._waiting = message.payload_as(NetsChanged)  # the newest is read next
        self._arrived.set()

    async def _follow(self) -> None:
        while True:
            await self._arrived.wait()
            self._arrived.clear()
            changed, self._waiting = self._waiting, None
            if changed is None or changed.version == self.version:
                continue
            prepared = await asyncio.to_thread(self.library.prepare, dict(changed.nets))
            problems = prepared if isinstance(prepared, list) else self.library.commit(prepared)
            if problems:
                said = [str(p) for p in problems]
                log.error("%s: nets version %d refused: %s", self.robot, changed.version, said)
                self.announce(said, changed.version)
                continue
            self.version = changed.version
            log.info("%s: now starting nets of library version %d", self.robot, self.version)
            self.announce()
