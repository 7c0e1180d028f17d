"""The only backend module that imports pymodbus (pinned >=3.16.1,<3.17: its API churns).

``ModuleClient`` is a small async client for one I/O module: connect, read a table range,
write one output. Every failure becomes one of two errors the rest of the backend understands:
``ModuleUnreachable`` (no connection, time-out) or ``ModuleExceptionAnswer`` (the module answered
with a Modbus exception code). After a time-out the connection is dropped, so a late answer can
never be taken for the answer to a later request.
"""

from __future__ import annotations

import asyncio
import logging

from pymodbus.client import AsyncModbusTcpClient
from pymodbus.exceptions import ModbusException
from pymodbus.pdu import ExceptionResponse

from guidebot.site.building import PointKind

__all__ = ["ModbusIOError", "ModuleClient", "ModuleExceptionAnswer", "ModuleUnreachable"]

EXCEPTION_NAMES = {
    1: "illegal function",
    2: "illegal data address",
    3: "illegal data value",
    4: "device failure",
    5: "acknowledge",
    6: "device busy",
    8: "memory parity error",
    10: "gateway path unavailable",
    11: "gateway target did not respond",
}


class ModbusIOError(Exception):
    """Base of the errors a module exchange can raise."""


class ModuleUnreachable(ModbusIOError):
    """No connection or no answer in time."""


class ModuleExceptionAnswer(ModbusIOError):
    """The module answered with a Modbus exception code."""

    def __init__(self, code: int, what: str) -> None:
        self.code = code
        name = EXCEPTION_NAMES.get(code, "unknown exception")
        super().__init__(f"Modbus exception {code} ({name}) on {what}")


class ModuleClient:
    """One connection to one module; one request at a time (pymodbus clients are not shared)."""

    def __init__(self, host: str, port: int, *, unit_id: int, timeout_s: float) -> None:
        self.host = host
        self.port = port
        self.unit_id = unit_id
        self.timeout_s = timeout_s
        self._client: AsyncModbusTcpClient | None = None
        self._lock = asyncio.Lock()
        # pymodbus logs each refused connect at error level; module health is reported instead.
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)

    @property
    def connected(self) -> bool:
        return self._client is not None and self._client.connected

    async def connect(self) -> None:
        """Open a fresh connection; raises ModuleUnreachable."""
        self.close()
        client = AsyncModbusTcpClient(
            self.host,
            port=self.port,
            timeout=self.timeout_s,
            retries=0,
            reconnect_delay=0,  # we reconnect ourselves, with back-off and health reports
        )
        try:
            ok = await asyncio.wait_for(client.connect(), self.timeout_s * 2)
        except (TimeoutError, OSError, ModbusException) as exc:
            client.close()
            raise ModuleUnreachable(f"cannot connect to {self.host}:{self.port}: {exc}") from None
        if not ok:
            client.close()
            raise ModuleUnreachable(f"cannot connect to {self.host}:{self.port}")
        self._client = client

    def close(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            client.close()

    async def read(self, kind: PointKind, address: int, count: int) -> list[int]:
        """Read ``count`` values of one table from ``address``; bits come back as 0/1."""
        what = f"read {kind.value} {address}..{address + count - 1}"
        async with self._lock:
            client = self._require()
            try:
                if kind == PointKind.discrete_input:
                    reply = await client.read_discrete_inputs(
                        address, count=count, device_id=self.unit_id
                    )
                elif kind == PointKind.coil:
                    reply = await client.read_coils(address, count=count, device_id=self.unit_id)
                elif kind == PointKind.input_register:
                    reply = await client.read_input_registers(
                        address, count=count, device_id=self.unit_id
                    )
                else:
                    reply = await client.read_holding_registers(
                        address, count=count, device_id=self.unit_id
                    )
            except (ModbusException, OSError, TimeoutError) as exc:
                self.close()
                raise ModuleUnreachable(f"{what}: {exc}") from None
            self._check(reply, what)
            if kind in (PointKind.discrete_input, PointKind.coil):
                return [int(bit) for bit in reply.bits[:count]]
            return list(reply.registers[:count])

    async def write(self, kind: PointKind, address: int, value: int) -> None:
        """Write one coil or holding register."""
        what = f"write {kind.value} {address} = {value}"
        async with self._lock:
            client = self._require()
            try:
                if kind == PointKind.coil:
                    reply = await client.write_coil(address, bool(value), device_id=self.unit_id)
                elif kind == PointKind.holding_register:
                    reply = await client.write_register(address, int(value), device_id=self.unit_id)
                else:
                    raise ModbusIOError(f"{kind.value} at {address} is read-only")
            except (ModbusException, OSError, TimeoutError) as exc:
                self.close()
                raise ModuleUnreachable(f"{what}: {exc}") from None
            self._check(reply, what)

    def _require(self) -> AsyncModbusTcpClient:
        if self._client is None or not self._client.connected:
            self.close()
            raise ModuleUnreachable(f"not connected to {self.host}:{self.port}")
        return self._client

    @staticmethod
    def _check(reply: object, what: str) -> None:
        if isinstance(reply, ExceptionResponse):
            raise ModuleExceptionAnswer(int(reply.exception_code), what)
        is_error = getattr(reply, "isError", None)
        if is_error is not None and is_error():
            raise ModuleExceptionAnswer(int(getattr(reply, "exception_code", 0)), what)
