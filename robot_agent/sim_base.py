"""A simulated differential base on the on-board bus: set_velocity in, odometry out.

It stands in for the RoboCAN base entity when the agent runs without RoboCAN (unit tests of
navigation, or a robot configured with ``can=None``). It integrates the commanded speeds in
robot time (scaled by the clock) and publishes odometry at a fixed wall rate; it honours a
stop on bumper_hit exactly like the RoboCAN master does.
"""

from __future__ import annotations

import asyncio
import math
import time

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.service import Service
from robot_agent.clock import Clock

__all__ = ["SimulatedBase"]


MAX_STEP_S = 0.1
"""Longest wall-clock step of the model: two periods at 20 Hz."""


class SimulatedBase(Service):
    """Unicycle model with acceleration limits; odometry starts at (0, 0, 0)."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        clock: Clock,
        *,
        rate_hz: float = 20.0,
        max_accel: float = 1.0,
        max_wacc: float = 3.0,
    ) -> None:
        super().__init__()
        self.ep = endpoint
        self.clock = clock
        self.period = 1.0 / rate_hz
        self.max_accel = max_accel
        self.max_wacc = max_wacc
        self.x = self.y = self.theta = 0.0
        self.v = self.w = 0.0
        self.v_cmd = self.w_cmd = 0.0
        self.velocity_commands = 0

    def _on_velocity(self, message: Message) -> None:
        self.v_cmd = float(message.payload.get("v", 0.0))
        self.w_cmd = float(message.payload.get("w", 0.0))
        self.velocity_commands += 1

    def _on_stop(self, _message: Message) -> None:
        self.v_cmd = self.w_cmd = self.v = self.w = 0.0

    async def on_start(self) -> None:
        self.subscribe(self.ep, "set_velocity", self._on_velocity)
        self.subscribe(self.ep, "bumper_hit", self._on_stop)
        self.spawn(self._run(), name="sim-base")

    def step(self, dt: float) -> None:
        """Advance the model by ``dt`` robot seconds."""
        dv = max(-self.max_accel * dt, min(self.max_accel * dt, self.v_cmd - self.v))
        dw = max(-self.max_wacc * dt, min(self.max_wacc * dt, self.w_cmd - self.w))
        self.v += dv
        self.w += dw
        self.theta = math.atan2(
            math.sin(self.theta + self.w * dt), math.cos(self.theta + self.w * dt)
        )
        self.x += self.v * math.cos(self.theta) * dt
        self.y += self.v * math.sin(self.theta) * dt

    async def _run(self) -> None:
        last = time.monotonic()
        while True:
            await asyncio.sleep(self.period)
            now = time.monotonic()
            # A stall of this process freezes the simulated world too (robot_agent/motion.py
            # does not count it against a goal): the base does not drive on blind through it.
            self.step(min(now - last, MAX_STEP_S) * self.clock.time_scale)
            last = now
            self.ep.publish(
                "odometry",
                {"x": self.x, "y": self.y, "theta": self.theta, "v": self.v, "w": self.w},
            )
