"""Simulated sonar ring (0x10, 0x20): firing sequence, ranges, bumpers."""

from __future__ import annotations

import logging

from robot_agent.robocan import protocol as p
from robot_agent.robocan.sim.host import next_slot
from robot_agent.robocan.sim.module import SimModule

__all__ = ["SonarRing"]

log = logging.getLogger(__name__)


class SonarRing(SimModule):
    """Sonars (eight by default) with a firing-sequence agent and eight bumpers (the PIC18
    module). It fires the sonars its firing order lists (all of them, in index order, until
    the master sends one); a sonar it does not fire reports 255, nothing in range."""

    def __init__(
        self,
        bus_spec: str,
        module_id: int,
        *,
        time_scale: float = 1.0,
        sonars: int = 8,
        flaws: frozenset[str] = frozenset(),
    ) -> None:
        super().__init__(bus_spec, module_id, time_scale=time_scale, flaws=flaws)
        self.description = p.Description(
            kind=p.ModuleKind.SONAR_RING,
            name=f"sonar_ring_{module_id:02x}",
            elements=(
                p.Element(p.ElementKind.SONAR, p.Role.COMPONENT, sonars),
                p.Element(p.ElementKind.FIRING_SEQUENCE, p.Role.AGENT, 1, 0b11),
                p.Element(p.ElementKind.BUMPER, p.Role.COMPONENT, 8),
            ),
        )
        self.ranges: list[float | None] = [3.0] * sonars
        self.bumpers = 0
        self.next_publish = 0.0

    @property
    def firing(self) -> bool:
        return self.enabled and self.modes.get(1) == 1

    def accept_config(self, element: int, number: int, data: bytes) -> bool:
        """Config 0 of the firing agent: each sonar index at most once, all of them real."""
        count = len(self.ranges)
        return (
            element == 1
            and number == 0
            and 1 <= len(data) <= count
            and len(set(data)) == len(data)
            and max(data) < count
        )

    def step(self, now: float, dt_sim: float) -> None:
        if self.firing and self.due(self.next_publish, now):
            self.next_publish = next_slot(self.next_publish, self.publish_period(0), now)
            order = self.firing_sequence
            fired = set(order) if order is not None else set(range(len(self.ranges)))
            values = [r if i in fired else None for i, r in enumerate(self.ranges)]
            for first in range(0, len(values), 5):
                self.send(p.sonar(0, first, values[first : first + 5]))

    def next_due(self) -> float:
        due = super().next_due()
        return min(due, self.next_publish) if self.firing else due

    def press_bumper(self, index: int, pressed: bool = True) -> None:
        self.bumpers = self.bumpers | (1 << index) if pressed else self.bumpers & ~(1 << index)
        if self.enabled:
            self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))

    def on_enabled(self) -> None:
        self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))

    @property
    def firing_sequence(self) -> bytes | None:
        return self.configs.get((1, 0))
