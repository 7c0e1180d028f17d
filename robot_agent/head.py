"""Head watchdog: the head is not critical, so a lost or refusing head must not stop a tour.

Gesture nets wait for servo_in_position after each move_servos. When the head module is
unplugged (or refuses a servo name) that answer never comes and the tour would hang. The
watchdog remembers every commanded servo; if the head driver has not confirmed it within
``timeout_s`` robot seconds (at least ``min_wall_s`` of wall time), it confirms it itself with
``degraded: true`` and counts it, so gestures are skipped and the tour goes on.
"""

from __future__ import annotations

import asyncio
import logging
from typing import Any

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.petri import ServoInPosition
from guidebot.service import Service
from robot_agent.clock import Clock

__all__ = ["HeadWatchdog"]

log = logging.getLogger(__name__)


class HeadWatchdog(Service):
    def __init__(
        self,
        endpoint: BusEndpoint,
        clock: Clock,
        *,
        timeout_s: float = 3.0,
        min_wall_s: float = 0.5,
        fitted: bool = True,
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.clock = clock
        self.timeout_s = timeout_s
        self.min_wall_s = min_wall_s
        self.fitted = fitted
        """False for a robot built without a head (a bare base): its skipped gestures are
        expected, not a fault worth a warning."""
        self.degraded = 0
        self._pending: dict[str, tuple[Any, asyncio.TimerHandle]] = {}

    async def on_start(self) -> None:
        if not self.fitted:
            log.info("this robot has no head: its gestures are skipped")
        self.subscribe(self.ep, "move_servos", self._on_move)
        self.subscribe(self.ep, "servo_in_position", self._on_in_position)

    async def on_stop(self) -> None:
        for _, timer in self._pending.values():
            timer.cancel()
        self._pending.clear()

    def _on_move(self, message: Message) -> None:
        servos = message.payload.get("servos")
        if not isinstance(servos, dict):
            return
        loop = asyncio.get_running_loop()
        delay = max(self.clock.wall(self.timeout_s), self.min_wall_s)
        for servo, position in servos.items():
            previous = self._pending.pop(str(servo), None)
            if previous is not None:
                previous[1].cancel()
            timer = loop.call_later(delay, self._expire, str(servo))
            self._pending[str(servo)] = (position, timer)

    def _on_in_position(self, message: Message) -> None:
        if message.source == self.ep.name:
            return
        entry = self._pending.pop(str(message.payload.get("servo")), None)
        if entry is not None:
            entry[1].cancel()

    def _expire(self, servo: str) -> None:
        entry = self._pending.pop(servo, None)
        if entry is None:
            return
        self.degraded += 1
        if self.fitted and (self.degraded == 1 or self.degraded % 100 == 0):
            log.warning(
                "head did not confirm servo %r (%d so far): gestures skipped", servo, self.degraded
            )
        self.ep.publish(ServoInPosition(servo=servo, position=entry[0], degraded=True))
