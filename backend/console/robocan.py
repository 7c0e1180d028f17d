"""The latest ``robocan_status`` of every robot (its CAN buses, counters and module tables), for
the console's robot view and ``GET /api/robots/{name}``: robots send it at most every few
seconds and at once when a module changes state (robot_agent.link), so the server keeps only
the last one, with the time it came."""

from __future__ import annotations

import logging
import time
from typing import Any

from pydantic import ValidationError

from guidebot.bus import Endpoint
from guidebot.messages import Message
from guidebot.payloads.robot import RobocanStatus
from guidebot.service import Service

__all__ = ["RobocanBook"]

log = logging.getLogger(__name__)


class RobocanBook(Service):
    """robot name -> (its last RobocanStatus, when it came)."""

    def __init__(self, endpoint: Endpoint) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.latest: dict[str, tuple[RobocanStatus, float]] = {}
        self.refused = 0

    async def on_start(self) -> None:
        self.subscribe(self.endpoint, "robocan_status", self._on_status, tap=True)

    def _on_status(self, message: Message) -> None:
        try:
            status = message.typed(RobocanStatus)
        except ValidationError as exc:
            self.refused += 1
            log.warning("robocan_status from %s refused: %s", message.source, exc.errors()[0])
            return
        # The hub refuses a robot naming another in ``robot``: the payload's name is its own.
        self.latest[status.robot] = (status, message.timestamp or time.time())

    def view(self, robot: str) -> dict[str, Any] | None:
        """The last status as JSON with ``at`` (when it was sent), or None if none came."""
        entry = self.latest.get(robot)
        if entry is None:
            return None
        status, at = entry
        return {**status.model_dump(mode="json"), "at": at}
