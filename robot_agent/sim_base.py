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
from robot_agent.robocan.sim.battery import SimBattery

__all__ = ["SimulatedBase", "SimulatedBattery"]


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


class SimulatedBattery(Service):
    """The battery of a bare simulated robot: RoboCAN's simulated battery module (``SimBattery``,
    its rates) without CAN, stepped on the robot's clock, so that it also follows a virtual
    clock (``guidebot plan --virtual``, docs/planning.md). Drains while the base moves (faster)
    or stands, charges while the charger contact is closed (``set_charging``), and publishes
    ``battery_level`` every ``period_s`` robot seconds and at once when charging starts or
    stops, as the battery entity does."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        clock: Clock,
        base: SimulatedBase,
        *,
        level: float = 1.0,
        period_s: float = 1.0,
    ) -> None:
        super().__init__()
        if not 0.0 <= level <= 1.0:
            raise ValueError(f"battery level must be within 0..1, got {level}")
        self.ep = endpoint
        self.clock = clock
        self.base = base
        self.level = level
        self.period_s = period_s
        self.charging = False
        self._last = 0.0

    async def on_start(self) -> None:
        self._last = self.clock.now()
        self.subscribe(self.ep, "set_charging", self._on_set_charging)
        self.spawn(self._run(), name="sim-battery")

    def _on_set_charging(self, message: Message) -> None:
        self.step()
        self.charging = bool(message.payload.get("on", False))
        # Reported after the handler returns, as the module's report comes back over CAN: the
        # battery monitor undocks while it publishes (it would hear the report in the middle).
        asyncio.get_running_loop().call_soon(self._publish)

    def step(self) -> None:
        """Drain or charge over the robot time since the last step, at the present motion."""
        now = self.clock.now()
        dt, self._last = now - self._last, now
        if self.charging:
            self.level = min(1.0, self.level + SimBattery.CHARGE * dt)
        else:
            moving = abs(self.base.v) + abs(self.base.w) > 0.01
            drain = SimBattery.MOVING_DRAIN if moving else SimBattery.IDLE_DRAIN
            self.level = max(0.0, self.level - drain * dt)

    def _publish(self) -> None:
        self.ep.publish(
            "battery_level",
            {"level": self.level, "charging": self.charging, "voltage": 22.0 + 4.0 * self.level},
        )

    async def _run(self) -> None:
        self._publish()
        while True:
            await self.clock.sleep(self.period_s)
            self.step()
            self._publish()
