"""A slave written from docs/robocan.md alone (raw frames, no simulator code) joins the master:
query, description block with a lost frame, enable, LED commands, time-out."""

from __future__ import annotations

import asyncio
import contextlib

import can

from guidebot.bus import Bus
from robot_agent.robocan import protocol as p
from robot_agent.robocan.blocks import BlockSender
from robot_agent.robocan.busopen import open_bus
from robot_agent.robocan.stack import RoboCanStack

from .conftest import Watch

MODULE = 0x60


class RawSlave:
    def __init__(self, channel: str) -> None:
        self.bus = open_bus(channel)
        self.bus.set_filters(
            [
                {"can_id": MODULE + 1, "can_mask": 0x7FF, "extended": False},
                {"can_id": p.BROADCAST_ID, "can_mask": 0x7FF, "extended": False},
            ]
        )
        self.reader = can.AsyncBufferedReader()
        self.notifier = can.Notifier(
            self.bus, [self.reader], timeout=0.05, loop=asyncio.get_running_loop()
        )

    def send(self, data: bytes) -> None:
        self.bus.send(can.Message(arbitration_id=MODULE, data=data, is_extended_id=False))

    async def expect(self, op: int, timeout: float = 5.0) -> bytes:
        """The next frame to us with this opcode (others, e.g. MASTER_START, are skipped)."""
        async with asyncio.timeout(timeout):
            while True:
                msg = await self.reader.get_message()
                if msg.data[0] == op:
                    return bytes(msg.data)

    async def close(self) -> None:
        await asyncio.to_thread(self.notifier.stop, 1.0)
        self.bus.shutdown()


async def test_spec_slave_with_a_lost_block_frame(onboard: Bus, channel: str, watch: Watch) -> None:
    async with RoboCanStack(onboard.endpoint("robocan"), [channel], simulate=False) as stack:
        slave = RawSlave(channel)
        try:
            slave.send(p.watchdog(p.SlaveState.DISABLED))
            await slave.expect(p.Op.QUERY)
            description = p.Description(
                kind=p.ModuleKind.OTHER,
                name="third_party_io_module",
                elements=(
                    p.Element(0xEE, p.Role.COMPONENT),  # a kind no driver knows
                    p.Element(p.ElementKind.LED, p.Role.COMPONENT, 4),
                ),
            )
            sender = BlockSender(p.BlockType.DESCRIPTION, description.encode())
            assert sender.frames >= 4
            slave.send(sender.start())
            flow = await slave.expect(p.Op.BLOCK_FLOW)
            assert flow[1] == p.FlowStatus.CONTINUE and flow[2] == 1
            for frame in sender.on_frame(flow):
                if frame[1] != 2:  # data frame 2 is lost on the wire
                    slave.send(frame)
            again = await slave.expect(p.Op.BLOCK_FLOW)
            assert again[2] == 2  # the master asks again from the missing frame
            for frame in sender.on_frame(again):
                slave.send(frame)
            end = await slave.expect(p.Op.BLOCK_END)
            assert end[1] == p.EndStatus.OK
            enable = await slave.expect(p.Op.ENABLE)
            assert enable == p.enable(p.MODULE, True)
            slave.send(p.ack(p.Op.ENABLE, p.MODULE))
            online = await watch.wait_for("module_status", watch.status(MODULE, "online"))
            assert online.payload["name"] == "third_party_io_module"
            row = next(r for r in stack.module_table() if r["module_id"] == MODULE)
            assert row["elements"] == ["kind_238", "led"]

            onboard.endpoint("nets").publish("set_leds", {"leds": {"eye_left": True}})
            assert await slave.expect(p.Op.SET_OUTPUT) == p.set_output(1, 0, 255)

            # the slave falls silent: lost within its time-out
            await watch.wait_for("module_status", watch.status(MODULE, "lost"), timeout=5)
        finally:
            await slave.close()


async def test_a_module_that_never_describes_itself_fails_and_is_retried(
    onboard: Bus, channel: str, watch: Watch
) -> None:
    async with RoboCanStack(onboard.endpoint("robocan"), [channel], simulate=False) as stack:
        slave = RawSlave(channel)

        async def watchdogs() -> None:
            while True:
                slave.send(p.watchdog(p.SlaveState.DISABLED))
                await asyncio.sleep(p.WATCHDOG_PERIOD_S)

        task = asyncio.create_task(watchdogs())
        try:
            # three queries, then the module is marked failed, then it is queried again
            for _ in range(4):
                await slave.expect(p.Op.QUERY, timeout=10)
            module = stack.masters[0].modules[MODULE]
            assert module.errors >= 1
            assert MODULE not in stack.online()
            assert not watch.of("module_status")  # never announced: nothing to report lost
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            await slave.close()
