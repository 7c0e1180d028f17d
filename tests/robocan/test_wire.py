"""A slave written from docs/robocan.md alone (raw frames, no simulator code) joins the master:
query, description block with a lost frame, enable, LED commands, time-out."""

from __future__ import annotations

import asyncio
import contextlib

from guidebot.bus import Bus
from robot_agent.robocan import protocol as p
from robot_agent.robocan.blocks import BlockSender
from robot_agent.robocan.stack import RoboCanStack

from .conftest import Watch
from .rawslave import RawSlave

MODULE = 0x60


async def test_spec_slave_with_a_lost_block_frame(onboard: Bus, channel: str, watch: Watch) -> None:
    async with RoboCanStack(onboard.endpoint("robocan"), [channel], simulate=False) as stack:
        slave = RawSlave(channel, MODULE)
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
            online = await watch.wait("module_status", watch.status(MODULE, "online"))
            assert online.payload["name"] == "third_party_io_module"
            row = next(r for r in stack.module_table() if r["module_id"] == MODULE)
            assert row["elements"] == ["kind_238", "led"]

            onboard.endpoint("nets").publish("set_leds", {"leds": {"eye_left": True}})
            assert await slave.expect(p.Op.SET_OUTPUT) == p.set_output(1, 0, 255)

            # the slave falls silent: lost within its time-out
            await watch.wait("module_status", watch.status(MODULE, "lost"), timeout=5)
        finally:
            await slave.close()


async def test_a_module_that_never_describes_itself_fails_and_is_retried(
    onboard: Bus, channel: str, watch: Watch
) -> None:
    async with RoboCanStack(onboard.endpoint("robocan"), [channel], simulate=False) as stack:
        slave = RawSlave(channel, MODULE)

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
