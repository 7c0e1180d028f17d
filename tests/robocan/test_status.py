"""The master's public face: module kind, firmware and counters through its API and on the
on-board bus (``robocan_status``), updated as modules are lost, re-queried or misbehave."""

from __future__ import annotations

from guidebot.bus import Bus
from guidebot.messages import Message
from robot_agent.robocan import protocol as p
from robot_agent.robocan.stack import RoboCanStack

from .conftest import Watch
from .rawslave import Tap


async def test_robocan_status_follows_losses_and_bad_frames(
    onboard: Bus, channel: str, watch: Watch, tap: Tap
) -> None:
    async with RoboCanStack(
        onboard.endpoint("robocan"), [channel], time_scale=10.0, status_period_s=0.05
    ) as stack:
        await stack.wait_online()
        await stack.unplug(0x40)
        await watch.wait("module_status", watch.status(0x40, "lost"))
        await stack.plug(0x40)
        await stack.wait_online({0x40})
        tap.send(0x40, p.mask_frame(p.Op.INPUTS, 0, 1))  # names the servo element: bad

        def settled(m: Message) -> bool:
            (bus,) = m.payload["buses"]
            return bus["counters"]["bad_frame"] >= 1 and any(
                row["module_id"] == 0x40 and row["state"] == "online" for row in bus["modules"]
            )

        message = await watch.wait("robocan_status", settled)
        assert message.payload["robot"] == "R1"
        (bus,) = message.payload["buses"]
        assert bus["bus"] == channel
        counters = bus["counters"]
        assert counters["modules_lost"] == 1 and counters["modules_requeried"] == 1
        assert counters["unknown_id"] == 0 and counters["block_errors"] == 0
        rows = {row["module_id"]: row for row in bus["modules"]}
        head = rows[0x40]
        assert head["kind"] == "head_io" and head["firmware"] == "1.0"
        assert head["lost"] == 1 and head["requeried"] == 1 and head["errors"] == 1
        assert rows[0x08]["kind"] == "battery_monitor" and rows[0x08]["lost"] == 0
        assert stack.status()["buses"][0]["modules"] == stack.module_table()
