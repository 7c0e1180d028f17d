"""``RoboCanStack``: what the robot agent starts. Opens the bus(es), runs one master per bus
and, when simulating, the simulated modules on the first (virtual) bus in this process.

    async with RoboCanStack(endpoint, buses=["virtual:R1"], simulate=True) as stack:
        await stack.wait_online({0x02, 0x04})
"""

from __future__ import annotations

import asyncio
import copy
import time
from pathlib import Path
from typing import Any

import can

from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.robot import RobocanStatus
from guidebot.service import Service
from robot_agent.robocan.busopen import open_bus, parse_bus_spec
from robot_agent.robocan.drivers import DriverConfig, DriverRegistry
from robot_agent.robocan.master import Master
from robot_agent.robocan.sim import BELLBOT, Simulator

__all__ = ["STATUS_PERIOD_S", "RoboCanStack", "start_master"]

STATUS_PERIOD_S = 1.0  # robocan_status on the on-board bus


class _LockedLogger(can.Listener):
    """One python-can log writer shared by several masters (each has its own lock)."""

    def __init__(self, path: Path) -> None:
        import threading

        self._logger = can.Logger(str(path))
        self._lock = threading.Lock()

    def on_message_received(self, msg: can.Message) -> None:
        if msg.channel is not None and not isinstance(msg.channel, int):
            msg = copy.copy(msg)  # BLF stores channels as numbers; a virtual channel is a name
            msg.channel = None
        with self._lock:
            self._logger.on_message_received(msg)

    def stop(self) -> None:
        with self._lock:
            self._logger.stop()


class RoboCanStack(Service):
    """Masters + optional simulated robot, as one async context manager."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        buses: list[str] | None = None,
        *,
        simulate: bool = True,
        time_scale: float = 1.0,
        config: DriverConfig | None = None,
        registry: DriverRegistry | None = None,
        record: str | Path | None = None,
        layout: dict[int, str] | None = None,
        status_period_s: float = STATUS_PERIOD_S,
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.bus_specs = list(buses or ["virtual:R1"])
        for spec in self.bus_specs:
            parse_bus_spec(spec)  # a bad string fails here, before anything starts
        if simulate and parse_bus_spec(self.bus_specs[0])[0] != "virtual":
            raise ValueError("simulated modules need a virtual bus (e.g. 'virtual:R1')")
        self.simulate = simulate
        self.time_scale = time_scale
        self.config = config or DriverConfig()
        self.registry = registry or DriverRegistry()
        self.record = Path(record) if record else None
        self.simulator = (
            Simulator(self.bus_specs[0], time_scale=time_scale, layout=layout or BELLBOT)
            if simulate
            else None
        )
        self.masters: list[Master] = []
        self._buses: list[can.BusABC] = []
        self._recorder: _LockedLogger | None = None
        self.status_period_s = status_period_s

    async def on_start(self) -> None:
        # Given back in reverse: subscriptions, the status task, then masters and modules.
        self.on_cleanup(self._stop_hardware)
        if self.record is not None:
            self._recorder = _LockedLogger(self.record)
        for spec in self.bus_specs:
            await self.start_master(spec)
        self.spawn(self._publish_status(), name="robocan-status")
        if self.simulator is not None:
            await self.simulator.start()
            self.subscribe(self.endpoint, "module_plug", self._on_plug)
            self.subscribe(self.endpoint, "sim_set_battery", self._on_set_battery)

    async def start_master(self, spec: str) -> Master:
        bus = open_bus(spec)
        self._buses.append(bus)
        master = Master(
            bus,
            self.endpoint,
            config=self.config,
            registry=self.registry,
            recorder=self._recorder,
            name=spec,
        )
        self.masters.append(master)
        await master.start()
        return master

    async def restart_master(self, index: int = 0) -> Master:
        """Stop one master and start a fresh one on the same bus (modules keep running)."""
        old = self.masters.pop(index)
        await old.stop()
        old.bus.shutdown()
        self._buses.remove(old.bus)
        return await self.start_master(self.bus_specs[index])

    async def _stop_hardware(self) -> None:
        # Masters first: a robot shutting down must not report every module lost and a base
        # fault on its way out.
        for master in self.masters:
            await master.stop()
        if self.simulator is not None:
            await self.simulator.stop()
        for bus in self._buses:
            bus.shutdown()
        self.masters.clear()
        self._buses.clear()
        if self._recorder is not None:
            self._recorder.stop()
            self._recorder = None

    # --- hot plug (simulation) -------------------------------------------------------

    async def plug(self, module_id: int) -> None:
        if self.simulator is None:
            raise RuntimeError("plug/unplug needs simulate=True")
        await self.simulator.plug(module_id)

    async def unplug(self, module_id: int) -> None:
        if self.simulator is None:
            raise RuntimeError("plug/unplug needs simulate=True")
        await self.simulator.unplug(module_id)

    async def set_enabled(self, module_id: int, on: bool) -> None:
        """Enable or disable a module through the master of the bus it is on."""
        for master in self.masters:
            if module_id in master.modules:
                await master.set_enabled(module_id, on)
                return
        raise KeyError(f"no module 0x{module_id:02X} on any bus")

    def set_battery_level(self, level: float) -> None:
        """Test hook: the simulated battery jumps to ``level`` (0..1) and reports it at once."""
        if self.simulator is None:
            raise RuntimeError("set_battery_level needs simulate=True")
        self.simulator.set_battery_level(level)

    def _on_plug(self, message: Message) -> None:
        module_id = message.payload.get("module_id")
        plugged = message.payload.get("plugged", True)
        if not isinstance(module_id, int) or self.simulator is None:
            return
        if module_id not in self.simulator.layout:
            return
        coro = self.plug(module_id) if plugged else self.unplug(module_id)
        task = asyncio.get_running_loop().create_task(coro)
        task.add_done_callback(lambda t: t.exception() if not t.cancelled() else None)

    def _on_set_battery(self, message: Message) -> None:
        level = message.payload.get("level")
        if isinstance(level, int | float) and not isinstance(level, bool):
            self.set_battery_level(float(level))

    # --- the module table ------------------------------------------------------------

    def module_table(self) -> list[dict[str, Any]]:
        return [row for master in self.masters for row in master.module_table()]

    def status(self) -> dict[str, Any]:
        """The payload of ``robocan_status``: per bus, the master's counters and its module
        table (kind, firmware, state, per-module counters). docs/messages.md."""
        return {"robot": self.config.robot, "buses": [m.status() for m in self.masters]}

    async def _publish_status(self) -> None:
        """``robocan_status`` on the on-board bus every ``status_period_s`` (for the staff
        console); a period, not a reaction: nothing waits on it."""
        while True:
            await asyncio.sleep(self.status_period_s)
            self.endpoint.publish(RobocanStatus.model_validate(self.status()))

    def online(self) -> set[int]:
        return set().union(*(m.online() for m in self.masters)) if self.masters else set()

    async def wait_online(self, module_ids: set[int] | None = None, timeout: float = 10.0) -> None:
        """Wait until these modules (default: the simulated layout) are online."""
        wanted = set(
            module_ids
            if module_ids is not None
            else (self.simulator.layout if self.simulator else ())
        )
        deadline = time.monotonic() + timeout
        while not wanted <= self.online():
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f"modules not online after {timeout} s: "
                    f"{sorted(f'0x{m:02X}' for m in wanted - self.online())}"
                )
            await asyncio.sleep(0.02)


def start_master(
    endpoint: BusEndpoint,
    buses: list[str] | None = None,
    *,
    simulate: bool = True,
    time_scale: float = 1.0,
    **kwargs: Any,
) -> RoboCanStack:
    """The agent's entry point: ``async with start_master(ep, simulate=True) as stack``."""
    return RoboCanStack(endpoint, buses, simulate=simulate, time_scale=time_scale, **kwargs)
