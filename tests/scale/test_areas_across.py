"""One restricted area, robots on two server processes (docs/scaling.md): they take turns; a
frozen leader (SIGSTOP past its lease) grants nothing when it wakes, and exits; a leader killed
(SIGKILL) while a robot holds the area does not lead to a second grant under the new leader."""

from __future__ import annotations

import itertools
from typing import Any

from backend.cluster import LOST_LEADERSHIP_EXIT
from bench.servers import ServerProcess, wait_until

from .cluster import WsClient

AREA = "corridor"  # the demo site's restricted corridor
TOKENS = {"R1": "robot-R1-demo-token", "R2": "robot-R2-demo-token"}
_sync = itertools.count()


async def _robot(server: ServerProcess, name: str) -> WsClient:
    return await WsClient.connect(server, TOKENS[name])


async def _synced(client: WsClient) -> None:
    """Once the server answers a ping, it has read everything the client sent before it."""
    ping_id = f"sync-{next(_sync)}"
    await client.send("ping", {}, id=ping_id)

    async def ponged() -> bool:
        return any(m.get("correlation_id") == ping_id for m in client.of_type("pong"))

    await wait_until(ponged, 20, "pong")


def _grants(client: WsClient) -> list[dict[str, Any]]:
    return [m for m in client.of_type("area_granted") if m["payload"]["area"] == AREA]


async def _granted(client: WsClient, count: int, what: str) -> None:
    async def enough() -> bool:
        return len(_grants(client)) >= count

    await wait_until(enough, 20, what)


async def _leads(server: ServerProcess) -> bool:
    health = await server.health()
    return bool(health and health["cluster"]["serving"])


async def _ask(client: WsClient, name: str) -> None:
    await client.send("request_area", {"robot": name, "area": AREA})
    await _synced(client)


async def _release(client: WsClient, name: str) -> None:
    await client.send("release_area", {"robot": name, "area": AREA})


async def test_robots_on_two_processes_take_turns_and_a_frozen_leader_grants_nothing(
    pair: list[ServerProcess],
) -> None:
    alpha, beta = pair
    await wait_until(lambda: _leads(alpha), 60, "alpha to lead")
    r1, r2 = await _robot(beta, "R1"), await _robot(alpha, "R2")
    try:
        # Turns under alpha: R1 (on beta, through the broker) first, R2 (on alpha) after it.
        await _ask(r1, "R1")
        await _granted(r1, 1, "R1's grant from the leader on the other process")
        await _ask(r2, "R2")
        assert _grants(r2) == []  # R1 holds it
        await _release(r1, "R1")
        await _granted(r2, 1, "R2's turn")
        await _release(r2, "R2")
        await _synced(r2)

        # Freeze the leader; R2's next request waits in its socket until alpha wakes.
        alpha.pause()
        try:
            await r2.send("request_area", {"robot": "R2", "area": AREA})
            await wait_until(lambda: _leads(beta), 30, "beta to lead after alpha's lease")
            await _ask(r1, "R1")
            await _granted(r1, 2, "R1's grant from the new leader")
        finally:
            alpha.resume()
        # Alpha wakes with a stale lock table (the corridor looks free) and R2's request: the
        # fence drops it, then alpha finds its lock gone and exits.
        assert alpha.process.wait(30) == LOST_LEADERSHIP_EXIT
        assert len(_grants(r2)) == 1, "the frozen leader granted the corridor R1 holds"

        # R2 comes back on beta and asks again; it gets the corridor once R1 leaves it.
        r2_again = await _robot(beta, "R2")
        try:
            await _ask(r2_again, "R2")
            assert _grants(r2_again) == []
            await _release(r1, "R1")
            await _granted(r2_again, 1, "R2's turn under the new leader")
        finally:
            await r2_again.close()
    finally:
        await r1.close()
        await r2.close()


async def test_leader_killed_while_a_robot_holds_the_area_no_second_grant(
    pair: list[ServerProcess],
) -> None:
    alpha, beta = pair
    await wait_until(lambda: _leads(alpha), 60, "alpha to lead")
    r1, r2 = await _robot(beta, "R1"), await _robot(beta, "R2")
    try:
        await _ask(r1, "R1")
        await _granted(r1, 1, "R1's grant")
        await r1.send("robot_state", {"robot": "R1", "node": "corridor_w", "areas": [AREA]})
        alpha.kill()
        await wait_until(lambda: _leads(beta), 30, "beta to lead")
        # The robot's resync (its next robot_state) tells the new leader what it holds.
        await r1.send("robot_state", {"robot": "R1", "node": "corridor_w", "areas": [AREA]})
        await _synced(r1)
        await _ask(r2, "R2")
        await _synced(r1)  # one more round trip: any grant R2 would get is on its way
        await _synced(r2)
        assert _grants(r2) == [], "the new leader granted the corridor R1 stands in"
        await r1.send("robot_state", {"robot": "R1", "node": "hall", "areas": []})
        await _granted(r2, 1, "R2's grant once R1 left the corridor")
    finally:
        await r1.close()
        await r2.close()
