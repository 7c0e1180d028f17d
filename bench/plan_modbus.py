"""The virtual plan's Modbus wire: the server's module client reading the building simulator's
module stores in-process instead of over Modbus/TCP.

In a virtual run (``bench.plan_virtual``) the plan owns both ends: the server's
``BuildingInterface`` and its pollers, and the ``BuildingSimulator`` whose module servers they
poll. Each poll (every module's ``sampling_period_ms``, 200 ms on the demo site) went through
pymodbus twice (the client's request, the simulator's server) and two sockets; over a 10-hour day
that was a quarter of the run's CPU and took no simulated time anyway (loopback, virtual clock).
``StoreClient`` has the surface the poller and the interface use (``backend.building._modbus
.ModuleClient``: connect, close, connected, read, write) and calls the very store methods the
simulator's Modbus server calls for each request (``ModuleStore.async_getValues`` /
``async_setValues``: same tables, same fault injection, same exception codes). The pollers, their
schedule, filters and health, the doors and elevators logic stay the server's own.
docs/planning.md, "The virtual run".
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterator
from typing import Any

from backend.building import poller as poller_module
from backend.building._modbus import ModbusIOError, ModuleExceptionAnswer, ModuleUnreachable
from building_sim._modbus import FaultKind, ModuleServer, ModuleStore
from building_sim.simulator import BuildingSimulator
from guidebot.site.building import PointKind

__all__ = ["StoreClient", "in_process_modbus"]

READ_CODES = {
    PointKind.coil: 1,
    PointKind.discrete_input: 2,
    PointKind.holding_register: 3,
    PointKind.input_register: 4,
}
"""Modbus function code of a read of each table (as pymodbus sends them)."""
WRITE_CODES = {PointKind.coil: 5, PointKind.holding_register: 6}
"""Function code of a write of one coil or one holding register."""


class StoreClient:
    """One module's client that calls the simulator's store of that module directly."""

    def __init__(
        self, server: ModuleServer, store: ModuleStore, *, unit_id: int, timeout_s: float
    ) -> None:
        self.server, self.store = server, store
        self.unit_id, self.timeout_s = unit_id, timeout_s
        self._open = False

    @property
    def connected(self) -> bool:
        # An unplugged module (fault "offline") closes every connection, as its server does.
        return self._open and self.server.online

    async def connect(self) -> None:
        """Raises ModuleUnreachable while the module is offline, as a refused connect does."""
        self._open = False
        if not self.server.online:
            raise ModuleUnreachable(f"cannot connect to 127.0.0.1:{self.server.port}")
        self._open = True

    def close(self) -> None:
        self._open = False

    async def read(self, kind: PointKind, address: int, count: int) -> list[int]:
        """Read ``count`` values of one table from ``address``; bits come back as 0/1."""
        what = f"read {kind.value} {address}..{address + count - 1}"
        self._require()
        values = await self._answer(
            self.store.async_getValues(self.unit_id, READ_CODES[kind], address, count), what
        )
        return [int(v) for v in values]

    async def write(self, kind: PointKind, address: int, value: int) -> None:
        """Write one coil or holding register."""
        what = f"write {kind.value} {address} = {value}"
        if kind not in WRITE_CODES:
            raise ModbusIOError(f"{kind.value} at {address} is read-only")
        self._require()
        await self._answer(
            self.store.async_setValues(self.unit_id, WRITE_CODES[kind], address, [int(value)]),
            what,
        )

    def _require(self) -> None:
        if not self.connected:
            self.close()
            raise ModuleUnreachable(f"not connected to 127.0.0.1:{self.server.port}")

    async def _answer(self, call: Any, what: str) -> Any:
        if self.store.fault.kind == FaultKind.slow:
            try:  # a module slower than the client's time-out is unreachable, as on the wire
                answer = await asyncio.wait_for(call, self.timeout_s)
            except TimeoutError:
                self.close()
                raise ModuleUnreachable(f"{what}: no answer in {self.timeout_s:g} s") from None
        else:
            answer = await call
        if answer is not None and not isinstance(answer, list):  # an exception code
            raise ModuleExceptionAnswer(int(answer), what)
        return answer


@contextlib.contextmanager
def in_process_modbus(building: BuildingSimulator) -> Iterator[None]:
    """While active, the server's pollers made for a module of ``building`` (by its port) get a
    StoreClient; a module elsewhere keeps the Modbus/TCP client."""
    by_port = {
        building.servers[m].port: (building.servers[m], building.stores[m]) for m in building.stores
    }
    wire = poller_module.ModuleClient

    def client(host: str, port: int, *, unit_id: int, timeout_s: float) -> Any:
        if host in ("127.0.0.1", "localhost") and port in by_port:
            server, store = by_port[port]
            return StoreClient(server, store, unit_id=unit_id, timeout_s=timeout_s)
        return wire(host, port, unit_id=unit_id, timeout_s=timeout_s)

    poller_module.ModuleClient = client  # type: ignore[assignment,misc]
    try:
        yield
    finally:
        poller_module.ModuleClient = wire  # type: ignore[misc]
