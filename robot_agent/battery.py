"""Battery logic: thresholds on the battery module's level, and the end of docking.

battery_level comes from the battery entity. Crossing ``low`` sends battery_low to the Task
Manager (finish the task, then charge); crossing ``panic`` sends battery_panic (cancel it and
charge now). Each alarm fires once per discharge and re-arms after charging above
``low + rearm``. While docked, the level reaching ``full`` ends the docking with ``charged``.
"""

from __future__ import annotations

import logging

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.petri import Charged
from guidebot.payloads.robot import BatteryAlarm
from guidebot.service import Service

__all__ = ["BatteryMonitor"]

log = logging.getLogger(__name__)


class BatteryMonitor(Service):
    def __init__(
        self,
        endpoint: BusEndpoint,
        robot: str,
        *,
        low: float = 0.3,
        panic: float = 0.1,
        full: float = 0.95,
        rearm: float = 0.05,
        alarms: bool = True,
    ) -> None:
        if not 0.0 <= panic < low < full <= 1.0:
            raise ValueError(f"need 0 <= panic < low < full <= 1, got {panic}, {low}, {full}")
        super().__init__()
        self.ep = endpoint
        self.robot = robot
        self.low = low
        self.panic = panic
        self.full = full
        self.rearm = rearm
        self.alarms = alarms
        """False when the battery entity already publishes the alarms (RoboCAN's driver)."""
        self.level: float | None = None
        self.charging = False
        self.docked_at: str | None = None
        self._low_sent = False
        self._panic_sent = False

    async def on_start(self) -> None:
        self.subscribe(self.ep, "battery_level", self._on_level)
        self.subscribe(self.ep, "docked", self._on_docked)

    def _on_docked(self, message: Message) -> None:
        self.docked_at = str(message.payload.get("station") or message.payload.get("node") or "")
        self.ep.publish("set_charging", {"on": True, "station": self.docked_at})
        self._check_charged()

    def undock(self) -> None:
        """Leaving the station (a task starts): open the charger contact."""
        if self.docked_at is not None:
            self.ep.publish("set_charging", {"on": False, "station": self.docked_at})
            self.docked_at = None

    def _on_level(self, message: Message) -> None:
        level = float(message.payload.get("level", 0.0))
        self.level = max(0.0, min(1.0, level))
        self.charging = bool(message.payload.get("charging", False))
        if self.level >= self.low + self.rearm:
            self._low_sent = self._panic_sent = False
        if not self.alarms:
            pass
        elif self.level <= self.panic and not self._panic_sent:
            self._panic_sent = self._low_sent = True
            log.warning("%s: battery panic at %.2f", self.robot, self.level)
            self.ep.publish(
                "battery_panic", BatteryAlarm(robot=self.robot, level=round(self.level, 3))
            )
        elif self.level <= self.low and not self._low_sent:
            self._low_sent = True
            log.info("%s: battery low at %.2f", self.robot, self.level)
            self.ep.publish(
                "battery_low", BatteryAlarm(robot=self.robot, level=round(self.level, 3))
            )
        self._check_charged()

    def _check_charged(self) -> None:
        if self.docked_at is not None and self.level is not None and self.level >= self.full:
            station = self.docked_at
            self.ep.publish(Charged(station=station, level=round(self.level, 3)))
            self.undock()
