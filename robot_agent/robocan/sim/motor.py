"""Simulated motor controller (0x02, 0x04): wheel velocity, encoder ticks, bumpers."""

from __future__ import annotations

import logging
from typing import Any

from robot_agent.robocan import protocol as p
from robot_agent.robocan.sim.host import next_slot
from robot_agent.robocan.sim.module import SimModule

__all__ = ["MotorController"]

log = logging.getLogger(__name__)


MAX_STEP_S = 0.1
"""Longest wall-clock step of the wheels' model (two encoder periods of 50 ms)."""


class MotorController(SimModule):
    """Motor + encoder, a velocity PID agent and four bumpers (the paper's dsPIC module)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """As ``SimModule`` (bus_spec, module_id, time_scale=, flaws=)."""
        super().__init__(*args, **kwargs)
        self.description = p.Description(
            kind=p.ModuleKind.MOTOR_CONTROLLER,
            name=f"motor_controller_{self.module_id:02x}",
            firmware=(2, 1),
            elements=(
                p.Element(p.ElementKind.MOTOR, p.Role.COMPONENT),
                p.Element(p.ElementKind.PID_VELOCITY, p.Role.AGENT, 1, 0b111),
                p.Element(p.ElementKind.BUMPER, p.Role.COMPONENT, 4),
            ),
        )
        self.target = 0.0
        self.velocity = 0.0
        self.distance = 0.0
        # Wall seconds the wheels' model has run since the last velocity command: the safety
        # time-out's clock. Like the wheels, it leaves out the part of a step over MAX_STEP_S
        # (a stall of the process, which delays the agent's commands too): on the wall clock,
        # a loaded machine's late commands stopped the robot again and again ("stuck").
        self.since_command = 0.0
        self.next_publish = 0.0
        self.bumpers = 0
        self.commands = 0

    @property
    def ticks_per_m(self) -> int:
        return self.param(0, p.Param.TICKS_PER_M)

    def on_command(self, op: int, data: bytes) -> p.AckStatus | None:
        if op == p.Op.SET_VELOCITY:
            _, velocity, _ = p.parse_set_velocity(data)
            self.commands += 1
            if self.enabled and self.modes.get(1) == 1:
                self.target = velocity
                self.since_command = 0.0
        return None  # velocity commands are not acknowledged: the next one follows soon

    def on_stop(self) -> None:
        self.target = 0.0
        self.velocity = 0.0

    def step(self, now: float, dt_sim: float) -> None:
        # A stall of the simulator's process freezes the wheels: no blind run at the last
        # command (robot_agent/motion.py does not count such a stall against a goal either).
        dt_sim = min(dt_sim, MAX_STEP_S * self.time_scale)
        self.since_command += dt_sim / self.time_scale
        timeout = self.param(1, p.Param.COMMAND_TIMEOUT_MS) / 1000
        timed_out = self.since_command > timeout and "no_command_timeout" not in self.flaws
        if self.target and timed_out:
            self.target = 0.0  # the agent's own safety time-out
        accel = self.param(1, p.Param.MAX_ACCEL) / 1000
        change = self.target - self.velocity
        limit = accel * dt_sim
        self.velocity += max(-limit, min(limit, change))
        self.distance += self.velocity * dt_sim
        if self.enabled and self.due(self.next_publish, now):
            self.next_publish = next_slot(self.next_publish, self.publish_period(0), now)
            ticks = round(self.distance * self.ticks_per_m)
            self.send(p.encoder(0, ticks, self.velocity))

    @property
    def active(self) -> bool:
        return bool(self.target or self.velocity)

    def next_due(self) -> float:
        due = super().next_due()
        return min(due, self.next_publish) if self.enabled else due

    def press_bumper(self, index: int, pressed: bool = True) -> None:
        """A physical contact (tests): the bumper frame goes out on the change, and a new
        contact stops this controller's motor by itself (it does not wait for the master)."""
        if pressed and not self.bumpers & (1 << index):
            self.target = 0.0
        self.bumpers = self.bumpers | (1 << index) if pressed else self.bumpers & ~(1 << index)
        if self.enabled:
            self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))

    def on_enabled(self) -> None:
        self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))
