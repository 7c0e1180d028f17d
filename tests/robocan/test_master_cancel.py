"""A caller cancelled while it waits on the master (a task stopped mid bring-up, an agent shutting
down) is really cancelled, even when the module's answer arrives in the same loop pass: on
Python 3.11 ``asyncio.wait_for`` returned the answer and swallowed the cancellation."""

from __future__ import annotations

import asyncio

import pytest

from guidebot.bus import Bus
from guidebot.testing import wait_until
from robot_agent.robocan import protocol as p
from robot_agent.robocan.busopen import open_bus
from robot_agent.robocan.master import CommandFailed, Master


async def test_a_command_cancelled_as_its_ack_arrives_is_cancelled(channel: str) -> None:
    bus = open_bus(channel)
    master = Master(bus, Bus().endpoint("robocan"), announce=False)
    await master.start()
    try:
        data = p.enable(p.MODULE, True)
        key = (0x02, data[0], data[1])
        caller = asyncio.create_task(master.command(0x02, data))
        await wait_until(lambda: key in master._acks)
        # The ACK and the cancellation in one loop pass, as when the reader delivers the ACK
        # while the caller's owner cancels it.
        master._acks[key].set_result(p.AckStatus.OK)
        caller.cancel()
        with pytest.raises(asyncio.CancelledError):
            await caller
        assert caller.cancelled()
    finally:
        await master.stop()
        bus.shutdown()


async def test_a_command_still_times_out_and_retries(channel: str) -> None:
    """The unhappy path the time-out exists for: no module answers, CommandFailed after the
    retries, nothing left pending."""
    bus = open_bus(channel)
    master = Master(bus, Bus().endpoint("robocan"), announce=False)
    await master.start()
    try:
        with pytest.raises(CommandFailed, match="did not acknowledge"):
            await master.command(0x02, p.enable(p.MODULE, True), retries=2)
        assert master._acks == {}
    finally:
        await master.stop()
        bus.shutdown()
