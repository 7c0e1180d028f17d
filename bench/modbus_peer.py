"""The peer of ``guidebot bench modbus --peer``: a plain pymodbus loop per module.

What a user would write with pymodbus alone: one ``AsyncModbusTcpClient`` per module, read the
tables, ``asyncio.sleep(period)``, repeat. No schedule (each cycle lasts period + the answer
time, so it drifts), no filter, no health, no reconnect policy.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

from pymodbus.client import AsyncModbusTcpClient

__all__ = ["plain_poll"]

Ranges = list[tuple[str, int, int]]  # (table, first address, count)


async def plain_poll(
    host: str,
    port: int,
    unit_id: int,
    ranges: Ranges,
    period_s: float,
    on_sample: Callable[[dict[str, list[int]], float], None],
) -> None:
    """Poll until cancelled; after each poll ``on_sample(values by table, its start time)``."""
    client = AsyncModbusTcpClient(host, port=port)
    await client.connect()
    try:
        while True:
            started = time.monotonic()
            sample: dict[str, list[int]] = {}
            for table, first, count in ranges:
                if table == "discrete_input":
                    reply = await client.read_discrete_inputs(first, count=count, device_id=unit_id)
                    sample[table] = [int(b) for b in reply.bits[:count]]
                elif table == "coil":
                    reply = await client.read_coils(first, count=count, device_id=unit_id)
                    sample[table] = [int(b) for b in reply.bits[:count]]
                elif table == "input_register":
                    reply = await client.read_input_registers(first, count=count, device_id=unit_id)
                    sample[table] = list(reply.registers[:count])
                else:
                    reply = await client.read_holding_registers(
                        first, count=count, device_id=unit_id
                    )
                    sample[table] = list(reply.registers[:count])
            on_sample(sample, started)
            await asyncio.sleep(period_s)
    finally:
        client.close()
