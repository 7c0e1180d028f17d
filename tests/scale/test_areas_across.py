"""One restricted area, robots on two server processes (docs/scaling.md): they take turns; a
frozen leader (SIGSTOP past its lease) grants nothing when it wakes, and exits; a leader killed
(SIGKILL) while a robot holds the area does not lead to a second grant under the new leader."""

from __future__ import annotations

from backend.cluster import LOST_LEADERSHIP_EXIT
from bench.cluster_clients import AreaRobot
from bench.servers import ServerProcess, wait_until


async def _leads(server: ServerProcess) -> bool:
    health = await server.health()
    return bool(health and health["cluster"]["serving"])


async def test_robots_on_two_processes_take_turns_and_a_frozen_leader_grants_nothing(
    pair: list[ServerProcess],
) -> None:
    alpha, beta = pair
    await wait_until(lambda: _leads(alpha), 60, "alpha to lead")
    r1, r2 = await AreaRobot.connect(beta, "R1"), await AreaRobot.connect(alpha, "R2")
    try:
        # Turns under alpha: R1 (on beta, through the broker) first, R2 (on alpha) after it.
        await r1.ask()
        await r1.granted(1, "R1's grant from the leader on the other process")
        await r2.ask()
        assert r2.grants() == 0  # R1 holds it
        await r1.release()
        await r2.granted(1, "R2's turn")
        await r2.release()

        # Freeze the leader; R2's next request waits in its socket until alpha wakes.
        alpha.pause()
        try:
            await r2.client.send("request_area", {"robot": "R2", "area": "corridor"})
            await wait_until(lambda: _leads(beta), 30, "beta to lead after alpha's lease")
            await r1.ask()
            await r1.granted(2, "R1's grant from the new leader")
        finally:
            alpha.resume()
        # Alpha wakes with a stale lock table (the corridor looks free) and R2's request: the
        # fence drops it, then alpha finds its lock gone and exits.
        assert alpha.process.wait(30) == LOST_LEADERSHIP_EXIT
        assert r2.grants() == 1, "the frozen leader granted the corridor R1 holds"

        # R2 comes back on beta and asks again; it gets the corridor once R1 leaves it.
        r2_again = await AreaRobot.connect(beta, "R2")
        try:
            await r2_again.ask()
            assert r2_again.grants() == 0
            await r1.release()
            await r2_again.granted(1, "R2's turn under the new leader")
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
    r1, r2 = await AreaRobot.connect(beta, "R1"), await AreaRobot.connect(beta, "R2")
    try:
        await r1.ask()
        await r1.granted(1, "R1's grant")
        await r1.report("corridor_w", holding=True)
        alpha.kill()
        await wait_until(lambda: _leads(beta), 30, "beta to lead")
        # The robot's resync (its next robot_state) tells the new leader what it holds.
        await r1.report("corridor_w", holding=True)
        await r2.ask()
        await r1.synced()  # one more round trip: any grant R2 would get is on its way
        await r2.synced()
        assert r2.grants() == 0, "the new leader granted the corridor R1 stands in"
        await r1.report("hall", holding=False)
        await r2.granted(1, "R2's grant once R1 left the corridor")
    finally:
        await r1.close()
        await r2.close()
