"""Simulated head and I/O module (0x40): servos, touch inputs, LEDs."""

from __future__ import annotations

import logging
from typing import Any

from robot_agent.robocan import protocol as p
from robot_agent.robocan.sim.module import SimModule

__all__ = ["HeadIo"]

log = logging.getLogger(__name__)


class HeadIo(SimModule):
    """Ten RC servos, six capacitive touch inputs and four outputs (eye LEDs...)."""

    SERVOS = 10
    TOP_SPEED = 360.0  # degrees/s: what SET_SERVO speed 0 means on this module

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """As ``SimModule`` (bus_spec, module_id, time_scale=, flaws=)."""
        super().__init__(*args, **kwargs)
        self.description = p.Description(
            kind=p.ModuleKind.HEAD_IO,
            name=f"head_io_{self.module_id:02x}",
            elements=(
                p.Element(p.ElementKind.SERVO, p.Role.COMPONENT, self.SERVOS),
                p.Element(p.ElementKind.TOUCH, p.Role.COMPONENT, 6),
                p.Element(p.ElementKind.LED, p.Role.COMPONENT, 4),
            ),
        )
        self.position = [0.0] * self.SERVOS
        self.target = [0.0] * self.SERVOS
        self.speed = [90.0] * self.SERVOS
        self.next_publish = [0.0] * self.SERVOS
        self.report = [False] * self.SERVOS
        self.touch_mask = 0
        self.outputs = [0] * 4

    def on_command(self, op: int, data: bytes) -> p.AckStatus | None:
        if op == p.Op.SET_SERVO and self.enabled:
            _, index, position, speed = p.parse_set_servo(data)
            if index < self.SERVOS:
                self.target[index] = position
                self.speed[index] = speed or self.TOP_SPEED  # 0 = as fast as it goes
                self.next_publish[index] = 0.0
                self.report[index] = True  # confirmed even when it is already there
        elif op == p.Op.SET_OUTPUT and self.enabled:
            if data[2] < len(self.outputs):
                self.outputs[data[2]] = data[3]
        return None

    def step(self, now: float, dt_sim: float) -> None:
        for i in range(self.SERVOS):
            if self.position[i] == self.target[i]:
                if self.report[i] and self.enabled:
                    self.report[i] = False
                    self.send(p.servo(0, i, self.position[i], True))
                continue
            move = self.speed[i] * dt_sim
            gap = self.target[i] - self.position[i]
            self.position[i] = (
                self.target[i]
                if abs(gap) <= move
                else self.position[i] + (move if gap > 0 else -move)
            )
            arrived = self.position[i] == self.target[i]
            if arrived:
                self.report[i] = False
            if self.enabled and (arrived or now >= self.next_publish[i]):
                self.next_publish[i] = now + 0.1
                self.send(p.servo(0, i, self.position[i], arrived))

    @property
    def active(self) -> bool:
        moving = any(pos != target for pos, target in zip(self.position, self.target, strict=True))
        return moving or (self.enabled and any(self.report))

    def on_enabled(self) -> None:
        self.send(p.mask_frame(p.Op.INPUTS, 1, self.touch_mask))

    def touch(self, index: int, pressed: bool = True) -> None:
        self.touch_mask = (
            self.touch_mask | (1 << index) if pressed else self.touch_mask & ~(1 << index)
        )
        if self.enabled:
            self.send(p.mask_frame(p.Op.INPUTS, 1, self.touch_mask))
