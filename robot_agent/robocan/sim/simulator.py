"""The simulated robot: the BellBot layout of modules on one virtual channel."""

from __future__ import annotations

import logging
from typing import Any

from robot_agent.robocan.sim.battery import SimBattery
from robot_agent.robocan.sim.head import HeadIo
from robot_agent.robocan.sim.host import SimHost
from robot_agent.robocan.sim.module import SimModule
from robot_agent.robocan.sim.motor import MotorController
from robot_agent.robocan.sim.sonar import SonarRing

__all__ = ["BELLBOT", "Simulator"]

log = logging.getLogger(__name__)

BELLBOT: dict[int, str] = {
    0x02: "motor",
    0x04: "motor",
    0x08: "battery",
    0x10: "sonar",
    0x20: "sonar",
    0x40: "head",
}


class Simulator:
    """The simulated robot: its modules on one virtual channel, plugged and unplugged at will.
    They share one ``SimHost`` (bus connection and scheduler)."""

    def __init__(
        self,
        bus_spec: str,
        *,
        time_scale: float = 1.0,
        layout: dict[int, str] | None = None,
        flaws: dict[int, frozenset[str]] | None = None,
    ) -> None:
        self.bus_spec = bus_spec
        self.time_scale = time_scale
        self.layout = dict(BELLBOT if layout is None else layout)
        self.flaws = dict(flaws or {})
        self.modules: dict[int, SimModule] = {}
        self.battery_level: float | None = None
        self.host = SimHost(bus_spec)

    def _make(self, module_id: int) -> SimModule:
        kind = self.layout.get(module_id)
        kwargs: dict[str, Any] = {
            "time_scale": self.time_scale,
            "flaws": self.flaws.get(module_id, frozenset()),
        }
        if kind == "motor":
            return MotorController(self.bus_spec, module_id, **kwargs)
        if kind == "sonar":
            return SonarRing(self.bus_spec, module_id, **kwargs)
        if kind == "head":
            return HeadIo(self.bus_spec, module_id, **kwargs)
        if kind == "battery":
            module = SimBattery(self.bus_spec, module_id, motion=self.motion, **kwargs)
            if self.battery_level is not None:
                module.level = self.battery_level
            return module
        raise KeyError(f"no simulated module 0x{module_id:02X} in this robot's layout")

    def motion(self) -> float:
        return sum(abs(m.velocity) for m in self.modules.values() if isinstance(m, MotorController))

    async def start(self) -> None:
        await self.host.start()
        for module_id in self.layout:
            await self.plug(module_id)

    async def stop(self) -> None:
        for module_id in list(self.modules):
            await self.unplug(module_id)
        await self.host.stop()

    async def plug(self, module_id: int) -> SimModule:
        """Power a module on (a fresh one: firmware state starts over). Idempotent."""
        module = self.modules.get(module_id)
        if module is not None:
            return module
        module = self._make(module_id)
        await module.start(self.host)
        self.modules[module_id] = module
        return module

    async def unplug(self, module_id: int) -> None:
        module = self.modules.pop(module_id, None)
        if module is not None:
            if isinstance(module, SimBattery):
                self.battery_level = module.level
            await module.stop()

    def set_battery_level(self, level: float) -> None:
        self.battery_level = level
        for module in self.modules.values():
            if isinstance(module, SimBattery):
                module.set_level(level)
