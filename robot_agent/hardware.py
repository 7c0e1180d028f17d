"""The hardware server layer of the agent: RoboCAN on a CAN bus, or a bare simulated base.

``RoboCANHardware`` opens the bus (``virtual:R1`` or ``socketcan:can0``), runs the RoboCAN
master whose entities speak the on-board bus, and with ``simulate=True`` also the simulated
BellBot modules on the same virtual channel. ``BareSimulation`` (no CAN at all) is a simulated
differential base only: for unit tests and for running many robots on a small machine.
"""

from __future__ import annotations

import logging
from typing import Any, Protocol

from guidebot.bus import Endpoint
from guidebot.service import Service
from robot_agent.clock import Clock
from robot_agent.sim_base import SimulatedBase, SimulatedBattery

__all__ = ["BareSimulation", "Hardware", "RoboCANHardware"]

log = logging.getLogger(__name__)


class Hardware(Protocol):
    async def start(self) -> None: ...

    async def stop(self) -> None: ...

    def describe(self) -> dict[str, Any]: ...


class BareSimulation(Service):
    """A simulated base on the on-board bus, without CAN."""

    def __init__(self, endpoint: Endpoint, clock: Clock, *, battery: float | None = None) -> None:
        super().__init__()
        self.base = SimulatedBase(endpoint, clock)
        self.battery = (
            None if battery is None else SimulatedBattery(endpoint, clock, self.base, level=battery)
        )
        """``battery``: a simulated battery starting at that level (None: no battery)."""

    async def on_start(self) -> None:
        await self.enter(self.base)
        if self.battery is not None:
            await self.enter(self.battery)

    def describe(self) -> dict[str, Any]:
        return {"kind": "bare-simulation", "velocity_commands": self.base.velocity_commands}


class RoboCANHardware(Service):
    """RoboCAN (robot_agent.robocan.RoboCanStack): master(s) and, simulated, the BellBot set."""

    def __init__(
        self,
        endpoint: Endpoint,
        clock: Clock,
        *,
        can: str,
        simulate: bool,
        robot: str,
        battery_low: float,
        battery_panic: float,
        battery_level: float | None = None,
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.clock = clock
        self.can_spec = can
        self.simulate = simulate
        self.robot = robot
        self.battery_low = battery_low
        self.battery_panic = battery_panic
        self.battery_level = battery_level
        self.stack: Any = None

    async def on_start(self) -> None:
        from robot_agent.robocan.drivers import DriverConfig
        from robot_agent.robocan.stack import RoboCanStack

        config = DriverConfig(
            robot=self.robot, battery_low=self.battery_low, battery_panic=self.battery_panic
        )
        self.stack = RoboCanStack(
            self.endpoint,
            [self.can_spec],
            simulate=self.simulate,
            time_scale=self.clock.time_scale,
            config=config,
        )
        if self.simulate and self.battery_level is not None:
            self.stack.simulator.battery_level = self.battery_level
        await self.enter(self.stack)
        if self.simulate:
            try:
                await self.stack.wait_online(timeout=20.0)
            except TimeoutError as exc:
                log.warning("%s: %s", self.robot, exc)

    def describe(self) -> dict[str, Any]:
        modules = self.stack.module_table() if self.stack is not None else []
        return {
            "kind": "robocan",
            "can": self.can_spec,
            "simulate": self.simulate,
            "modules": modules,
        }
