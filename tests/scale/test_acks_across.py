"""A robot's must-arrive messages across processes (docs/protocol.md "Delivery guarantee",
docs/scaling.md): the hub acknowledges one once the deciding components have handled it, so a
robot on a follower is acknowledged by the leader, through the broker. While no process
decides (a fail-over) nothing is acknowledged: the robot's link sends the message again, and
the new leader handles it. Copies are handled once."""

from __future__ import annotations

import asyncio
import itertools
from typing import Any

from backend.cluster import LOST_LEADERSHIP_EXIT
from bench.cluster_clients import AREA, AreaRobot
from bench.servers import ServerProcess, wait_until

_ids = itertools.count()


async def _leads(server: ServerProcess) -> bool:
    health = await server.health()
    return bool(health and health["cluster"]["serving"])


def _acks(robot: AreaRobot, message_id: str) -> list[dict[str, Any]]:
    return [m for m in robot.client.of_type("ack") if m["payload"].get("message_id") == message_id]


async def _send(robot: AreaRobot, type_: str, message_id: str) -> None:
    """One copy of a must-arrive message, with the id its link keeps for every copy."""
    await robot.client.send(type_, {"robot": robot.name, "area": AREA}, id=message_id)
    await robot.synced()


async def test_a_robot_on_a_follower_is_acknowledged_by_the_leader_once_per_copy(
    pair: list[ServerProcess],
) -> None:
    alpha, beta = pair
    await wait_until(lambda: _leads(alpha), 60, "alpha to lead")
    r1 = await AreaRobot.connect(beta, "R1")
    try:
        asked = f"ask-{next(_ids)}"
        await _send(r1, "request_area", asked)
        await r1.granted(1, "R1's grant from alpha")
        await wait_until(lambda: _true(_acks(r1, asked)), 10, "the ack from the leader")
        assert _acks(r1, asked)[0]["source"] == "hub"

        # A copy sent again (its ack was late) is acknowledged again, not handled twice: a
        # second release would be refused with an error, since R1 no longer holds it.
        released = f"release-{next(_ids)}"
        await _send(r1, "release_area", released)
        await _send(r1, "release_area", released)
        await wait_until(lambda: _true(len(_acks(r1, released)) == 2), 10, "two acks")
        await r1.synced()
        assert r1.client.of_type("error") == []
    finally:
        await r1.close()


async def test_nothing_is_acknowledged_while_no_process_decides(
    pair: list[ServerProcess],
) -> None:
    alpha, beta = pair
    await wait_until(lambda: _leads(alpha), 60, "alpha to lead")
    r1 = await AreaRobot.connect(beta, "R1")
    try:
        alpha.pause()  # the leader decides nothing now; beta leads after alpha's lease
        try:
            asked = f"ask-{next(_ids)}"
            await _send(r1, "request_area", asked)
            await asyncio.sleep(0.5)
            assert not await _leads(beta), "beta led too soon for this test"
            assert _acks(r1, asked) == [], "a follower acknowledged what nobody handled"
            await wait_until(lambda: _leads(beta), 30, "beta to lead after alpha's lease")
            # R1's link has no ack: it sends the same message again, and the new leader
            # grants the corridor.
            await _send(r1, "request_area", asked)
            await r1.granted(1, "R1's grant from beta")
            await wait_until(lambda: _true(_acks(r1, asked)), 10, "the ack from beta")
        finally:
            alpha.resume()
        assert await asyncio.to_thread(alpha.process.wait, 30) == LOST_LEADERSHIP_EXIT
        await r1.synced()
        assert r1.grants() == 1
    finally:
        await r1.close()


async def _true(value: object) -> object:
    return value
