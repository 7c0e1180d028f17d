"""Simulated battery monitor (0x08). Named ``SimBattery`` so that it does not clash with
the robot agent's ``robot_agent.battery.BatteryMonitor``, which reads it through the bus.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from robot_agent.robocan import protocol as p
from robot_agent.robocan.sim.host import next_slot
from robot_agent.robocan.sim.module import SimModule

__all__ = ["SimBattery"]

log = logging.getLogger(__name__)


class SimBattery(SimModule):
    """Battery level and charger contact. Drains while the base moves, charges when docked."""

    IDLE_DRAIN = 1 / (8 * 3600)  # per simulated second
    MOVING_DRAIN = 1 / (2 * 3600)
    CHARGE = 1 / 3600

    def __init__(
        self,
        bus_spec: str,
        module_id: int,
        *,
        time_scale: float = 1.0,
        motion: Callable[[], float] = lambda: 0.0,
        flaws: frozenset[str] = frozenset(),
    ) -> None:
        super().__init__(bus_spec, module_id, time_scale=time_scale, flaws=flaws)
        self.description = p.Description(
            kind=p.ModuleKind.BATTERY_MONITOR,
            name=f"battery_{module_id:02x}",
            elements=(p.Element(p.ElementKind.BATTERY, p.Role.COMPONENT),),
        )
        self.level = 1.0
        self.charging = False
        self.motion = motion
        self.next_publish = 0.0

    def on_command(self, op: int, data: bytes) -> p.AckStatus | None:
        if op == p.Op.SET_CHARGING:
            self.charging = bool(data[1])
            self.next_publish = 0.0  # report the new state at once
            return p.AckStatus.OK
        return None

    def set_level(self, level: float) -> None:
        self.level = max(0.0, min(1.0, level))
        self.next_publish = 0.0
        self.poke()

    def step(self, now: float, dt_sim: float) -> None:
        if self.charging:
            self.level = min(1.0, self.level + self.CHARGE * dt_sim)
        else:
            moving = self.motion() > 0.01
            drain = self.MOVING_DRAIN if moving else self.IDLE_DRAIN
            self.level = max(0.0, self.level - drain * dt_sim)
        if self.enabled and self.due(self.next_publish, now):
            self.next_publish = next_slot(self.next_publish, self.publish_period(0), now)
            self.send(p.battery(self.level, 22.0 + 4.0 * self.level, self.charging))

    def next_due(self) -> float:
        due = super().next_due()
        return min(due, self.next_publish) if self.enabled else due
