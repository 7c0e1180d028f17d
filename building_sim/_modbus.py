"""The only simulator module that imports pymodbus: a Modbus/TCP server over a plain store.

pymodbus 3.16 serves a ``SimCore``; its request handlers only call ``async_getValues`` and
``async_setValues`` on ``server.context``. We put our own store there so the simulated devices
can change inputs at any time, answer slowly or answer with an exception code (fault injection).
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum

from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from guidebot.site.building import BuildingModule, PointKind

__all__ = ["FaultKind", "ModuleFault", "ModuleServer", "ModuleStore"]

# Modbus function code -> data table.
_READ = {1: PointKind.coil, 2: PointKind.discrete_input, 3: PointKind.holding_register}
_READ[4] = PointKind.input_register
_WRITE = {5: PointKind.coil, 15: PointKind.coil, 6: PointKind.holding_register}
_WRITE[16] = PointKind.holding_register
_BITS = frozenset({PointKind.coil, PointKind.discrete_input})

WriteHook = Callable[[PointKind, int, int], None]


class FaultKind(StrEnum):
    """What an injected fault does to a module."""

    none = "none"
    offline = "offline"  # the listening socket closes: connections are refused
    slow = "slow"  # every answer is delayed by delay_ms
    exception = "exception"  # every request gets a Modbus exception answer


@dataclass
class ModuleFault:
    kind: FaultKind = FaultKind.none
    delay_ms: float = 0.0
    code: int = int(ExcCodes.DEVICE_FAILURE)


class ModuleStore:
    """The four data tables of one I/O module, sized like a real module from its points.

    Tables are padded to whole 16-bit words for bits; addresses past the end answer
    ILLEGAL_ADDRESS, as a real module does.
    """

    def __init__(self, module: BuildingModule) -> None:
        self.module_id = module.id
        self.tables: dict[PointKind, list[int]] = {}
        for kind in PointKind:
            top = max((p.address for p in module.points if p.kind == kind), default=-1) + 1
            if kind in _BITS:
                top = (top + 15) // 16 * 16
            self.tables[kind] = [0] * top
        self.fault = ModuleFault()
        self.on_write: WriteHook | None = None
        self.requests = 0

    def get(self, kind: PointKind, address: int) -> int:
        return self.tables[kind][address]

    def set(self, kind: PointKind, address: int, value: int) -> None:
        """Change a value from the simulated device side (a sensor, a button, a cabin)."""
        self.tables[kind][address] = int(value)

    async def _faults(self) -> ExcCodes | None:
        self.requests += 1
        fault = self.fault
        if fault.kind == FaultKind.slow and fault.delay_ms > 0:
            await asyncio.sleep(fault.delay_ms / 1000)
        if fault.kind == FaultKind.exception:
            return ExcCodes(fault.code)
        return None

    async def async_getValues(
        self, device_id: int, func_code: int, address: int, count: int = 1
    ) -> list[int] | list[bool] | ExcCodes:
        if (code := await self._faults()) is not None:
            return code
        kind = _READ.get(func_code) or _WRITE.get(func_code)
        if kind is None:
            return ExcCodes.ILLEGAL_FUNCTION
        table = self.tables[kind]
        if address < 0 or count < 1 or address + count > len(table):
            return ExcCodes.ILLEGAL_ADDRESS
        values = table[address : address + count]
        return [bool(v) for v in values] if kind in _BITS else values

    async def async_setValues(
        self, device_id: int, func_code: int, address: int, values: Sequence[int] | Sequence[bool]
    ) -> ExcCodes | None:
        if (code := await self._faults()) is not None:
            return code
        kind = _WRITE.get(func_code)
        if kind is None:
            return ExcCodes.ILLEGAL_FUNCTION
        table = self.tables[kind]
        if address < 0 or address + len(values) > len(table):
            return ExcCodes.ILLEGAL_ADDRESS
        for offset, value in enumerate(values):
            table[address + offset] = int(value)
            if self.on_write is not None:
                self.on_write(kind, address + offset, int(value))
        return None

    def device_ids(self) -> list[int]:
        return [0]


class ModuleServer:
    """One Modbus/TCP server on 127.0.0.1 for one module; can go offline and come back."""

    def __init__(self, store: ModuleStore, *, host: str = "127.0.0.1", port: int = 0) -> None:
        self.store = store
        self.host = host
        self.port = port
        self._server: ModbusTcpServer | None = None

    @property
    def online(self) -> bool:
        return self._server is not None

    async def start(self) -> int:
        """Listen (again); returns the bound port, which stays the same across restarts."""
        if self._server is not None:
            return self.port
        placeholder = SimDevice(id=0, simdata=SimData(0, values=0, datatype=DataType.REGISTERS))
        server = ModbusTcpServer(placeholder, address=(self.host, self.port))
        server.context = self.store  # type: ignore[assignment]
        await server.serve_forever(background=True)
        listener = server.transport
        sockets = getattr(listener, "sockets", None)
        if sockets:
            self.port = int(sockets[0].getsockname()[1])
        self._server = server
        return self.port

    async def stop(self) -> None:
        """Close the listener and every open connection (the module is unplugged)."""
        server, self._server = self._server, None
        if server is not None:
            await server.shutdown()
