"""BuildingSimulator: every I/O module of a site as a Modbus/TCP server, with live devices.

    async with BuildingSimulator(config, time_scale=10, port_zero=True) as sim:
        site_for_server = sim.bound_config()     # same site, real ports
        sim.press("B1", ms=300)

Used by the CLI, the demo launcher, the BuildingInterface tests and the robot-agent tests.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
from collections.abc import Callable
from typing import Any

from building_sim._modbus import FaultKind, ModuleFault, ModuleServer, ModuleStore
from building_sim.devices import DoorSim, ElevatorSim
from guidebot.service import Service
from guidebot.site.building import IORef, PointKind
from guidebot.site.building_config import BuildingConfig
from guidebot.site.io_rules import Role, allowed

__all__ = ["BuildingSimulator", "SimulatorError"]

DEFAULT_ELEVATOR_HOLD_S = 8.0
HOLD_STEP_S = 0.05
"""How often a held button counts the time it has been held."""
MAX_HOLD_STEP_S = 0.1
"""The most a held button counts at one step. A stall of the simulator's process freezes its
hand, as it freezes the simulated base (robot_agent/sim_base.py): where the server's poller
shares the process (the test fleets), a stall stopped the poller but not the press, whose
release then came before the next sample, and an 800 ms press was never seen (CI)."""


class SimulatorError(LookupError):
    """An unknown button, module, point or door was named."""


class BuildingSimulator(Service):
    """The whole building: one ModuleServer per module, doors, elevators and buttons."""

    def __init__(
        self,
        config: BuildingConfig,
        *,
        time_scale: float = 1.0,
        port_zero: bool = False,
        door_hold_s: float | None = None,
        elevator_hold_s: float = DEFAULT_ELEVATOR_HOLD_S,
    ) -> None:
        super().__init__()
        if time_scale <= 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale}")
        self.config = config.check()
        self.time_scale = time_scale
        self.stores = {m.id: ModuleStore(m) for m in config.modules}
        self.servers = {
            m.id: ModuleServer(self.stores[m.id], host="127.0.0.1", port=0 if port_zero else m.port)
            for m in config.modules
        }
        self._hooks: dict[tuple[str, PointKind, int], Callable[[int], None]] = {}
        self.doors = {
            d.id: DoorSim(d, self.write, time_scale=time_scale, hold_s=door_hold_s)
            for d in config.doors
        }
        for door_sim in self.doors.values():
            self._hook(door_sim.door.open, door_sim.on_open_coil)
        self.elevators: dict[str, ElevatorSim] = {}
        for elevator in config.elevators:
            first = elevator.stops[0].call.module
            regs = (
                self._optional(first, f"{elevator.id}_floor", Role.elevator_floor),
                self._optional(first, f"{elevator.id}_door", Role.elevator_door),
            )
            sim = ElevatorSim(
                elevator, self.write, time_scale=time_scale, hold_s=elevator_hold_s, registers=regs
            )
            self.elevators[elevator.id] = sim
            for index, stop in enumerate(elevator.stops):
                self._hook(stop.call, functools.partial(sim.on_call, index))
        self.buttons = {b.id: b for b in config.buttons}
        self.presses = 0
        self._releases: dict[str, asyncio.Task[None]] = {}
        for module_id, store in self.stores.items():
            store.on_write = functools.partial(self._written, module_id)

    def _optional(self, module_id: str, name: str, role: Role) -> IORef | None:
        point = self.config.module(module_id).point(name)
        if point is None or not allowed(role, point.kind):
            return None
        return IORef(module=module_id, point=name)

    def _hook(self, ref: IORef, handler: Callable[[int], None]) -> None:
        _, point = self.config.resolve(ref)
        self._hooks[(ref.module, point.kind, point.address)] = handler

    def _written(self, module_id: str, kind: PointKind, address: int, value: int) -> None:
        handler = self._hooks.get((module_id, kind, address))
        if handler is not None:
            handler(value)

    # -- life cycle ----------------------------------------------------------------------------

    async def on_start(self) -> None:
        for server in self.servers.values():
            await server.start()
            self.on_cleanup(functools.partial(_stop_quietly, server))

    async def on_stop(self) -> None:
        for handle in self._releases.values():
            handle.cancel()
        self._releases.clear()
        for device in (*self.doors.values(), *self.elevators.values()):
            device.cancel()

    # -- what the outside sees -----------------------------------------------------------------

    @property
    def ports(self) -> dict[str, int]:
        """Bound port of each module (the site's port unless port_zero)."""
        return {module_id: server.port for module_id, server in self.servers.items()}

    def bound_config(self) -> BuildingConfig:
        """The site's building part with host and port set to where this simulator listens."""
        modules = [
            m.model_copy(update={"host": "127.0.0.1", "port": self.servers[m.id].port})
            for m in self.config.modules
        ]
        return self.config.model_copy(update={"modules": modules})

    def read(self, ref: IORef) -> int:
        _, point = self._resolve(ref)
        return self.stores[ref.module].get(point.kind, point.address)

    def read_point(self, module: str, point: str) -> int:
        return self.read(IORef(module=module, point=point))

    def write(self, ref: IORef, value: int) -> None:
        """Set a point from the device side (inputs) or as a wire would (outputs)."""
        _, point = self._resolve(ref)
        self.stores[ref.module].set(point.kind, point.address, value)

    def _resolve(self, ref: IORef) -> tuple[Any, Any]:
        try:
            return self.config.resolve(ref)
        except KeyError:
            raise SimulatorError(f"no point {ref.point!r} on module {ref.module!r}") from None

    def press(self, button: str, ms: float = 300.0) -> None:
        """Hold a button's input for ``ms`` milliseconds (real time: a hand is not scaled; it
        stops while the simulator's process is stalled, ``MAX_HOLD_STEP_S``)."""
        if button not in self.buttons:
            raise SimulatorError(f"no button {button!r}; known: {sorted(self.buttons)}")
        if ms <= 0:
            raise ValueError(f"press duration must be > 0 ms, got {ms}")
        ref = self.buttons[button].input
        self.write(ref, 1)
        self.presses += 1
        old = self._releases.pop(button, None)
        if old is not None:
            old.cancel()
        self._releases[button] = asyncio.get_running_loop().create_task(
            self._hold(button, ms / 1000), name=f"press-{button}"
        )

    async def _hold(self, button: str, seconds: float) -> None:
        """Release the button once it has been held ``seconds`` of the simulator's time."""
        loop = asyncio.get_running_loop()
        held, last = 0.0, loop.time()
        while held < seconds:
            await asyncio.sleep(min(HOLD_STEP_S, seconds - held))
            now = loop.time()
            held += min(now - last, MAX_HOLD_STEP_S)
            last = now
        self._releases.pop(button, None)
        self.write(self.buttons[button].input, 0)

    def jam_door(self, door: str, jammed: bool = True) -> None:
        """A jammed door ignores its open coil (a door that fails to open)."""
        if door not in self.doors:
            raise SimulatorError(f"no door {door!r}; known: {sorted(self.doors)}")
        self.doors[door].jammed = jammed

    def stick_elevator(self, elevator: str, stuck: bool = True) -> None:
        """A stuck elevator keeps its calls but never arrives until freed."""
        if elevator not in self.elevators:
            raise SimulatorError(f"no elevator {elevator!r}; known: {sorted(self.elevators)}")
        self.elevators[elevator].set_stuck(stuck)

    async def set_fault(
        self, module: str, kind: FaultKind | str, *, delay_ms: float = 0.0, code: int = 4
    ) -> None:
        """Inject (or clear, with kind "none") a fault on one module."""
        if module not in self.stores:
            raise SimulatorError(f"no module {module!r}; known: {sorted(self.stores)}")
        kind = FaultKind(kind)
        if not 1 <= code <= 11:
            raise ValueError(f"Modbus exception code must be 1..11, got {code}")
        self.stores[module].fault = ModuleFault(kind=kind, delay_ms=delay_ms, code=code)
        server = self.servers[module]
        if kind == FaultKind.offline:
            await server.stop()
        else:
            await server.start()

    def state(self) -> dict[str, Any]:
        """A JSON-able snapshot for the control API and demos."""
        return {
            "time_scale": self.time_scale,
            "modules": {
                module_id: {
                    "port": self.servers[module_id].port,
                    "online": self.servers[module_id].online,
                    "fault": store.fault.kind.value,
                    "requests": store.requests,
                    "points": {
                        p.name: store.get(p.kind, p.address)
                        for p in self.config.module(module_id).points
                    },
                }
                for module_id, store in self.stores.items()
            },
            "doors": {d: s.state.value for d, s in self.doors.items()},
            "elevators": {
                e: {
                    "floor": s.floor,
                    "state": s.state.value,
                    "pending": sorted(s.pending),
                    "stuck": s.stuck,
                }
                for e, s in self.elevators.items()
            },
            "buttons": {b: bool(self.read(btn.input)) for b, btn in self.buttons.items()},
        }


async def _stop_quietly(server: ModuleServer) -> None:
    """A module server that fails to stop must not keep the others running."""
    with contextlib.suppress(Exception):
        await server.stop()
