"""One restricted area, robots on two server processes (docs/scaling.md): they take turns; a
frozen leader (SIGSTOP past its lease) grants nothing when it wakes, and exits; a leader killed
(SIGKILL) while a robot holds the area does not lead to a second grant under the new leader, who
restores from the event log the lock of a robot whose link died with the old leader."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx

from backend.cluster import LOST_LEADERSHIP_EXIT
from bench.cluster_clients import AreaRobot
from bench.servers import ADMIN_TOKEN, ServerProcess, start_servers, wait_until
from tests.server.postgres import PostgresServer

from .redis import RedisServer

AUTH = {"Authorization": f"Bearer {ADMIN_TOKEN}"}


async def test_robots_on_two_processes_take_turns_and_a_frozen_leader_grants_nothing(
    pair: list[ServerProcess],
) -> None:
    alpha, beta = pair
    await alpha.until(alpha.leads, "alpha to lead")
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
            await beta.until(beta.leads, "beta to lead after alpha's lease")
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
    await alpha.until(alpha.leads, "alpha to lead")
    r1, r2 = await AreaRobot.connect(beta, "R1"), await AreaRobot.connect(beta, "R2")
    try:
        await r1.ask()
        await r1.granted(1, "R1's grant")
        await r1.report("corridor_w", holding=True)
        alpha.kill()
        await beta.until(beta.leads, "beta to lead")
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


async def test_the_new_leader_restores_the_lock_of_a_robot_that_lost_its_link(
    redis: RedisServer, postgres: PostgresServer, tmp_path: Path
) -> None:
    """R1, linked to the leader, holds the corridor; the leader's death takes R1's link with it,
    so only the event log tells the new leader who holds the corridor (docs/scaling.md). Its
    wait for the robots' resync is cut to 1 s: after it, the restored lock alone keeps R2 out."""
    env = {"GUIDEBOT_LOCK_RESYNC_S": "1"}
    db = postgres.database()
    async with start_servers(["alpha", "beta"], db, redis.url, tmp_path, env=env) as pair:
        alpha, beta = pair
        await alpha.until(alpha.leads, "alpha to lead")
        r1, r2 = await AreaRobot.connect(alpha, "R1"), await AreaRobot.connect(beta, "R2")
        try:
            await r1.ask()
            await r1.granted(1, "R1's grant")
            await r1.report("corridor_w", holding=True)
            alpha.kill()
            await beta.until(beta.leads, "beta to lead")
            corridor = await _corridor(beta)
            assert corridor["holder"] == "R1" and corridor["entered"], corridor
            assert corridor["state"] == "holder_offline", corridor  # until R1 reports again
            await r2.report("hall", holding=False)
            await r2.ask()  # held back until R1 resyncs or 1 s has passed, then queued

            async def r2_queued() -> dict[str, Any] | None:
                corridor = await _corridor(beta)
                return corridor if corridor["waiting"] == ["R2"] else None

            corridor = await wait_until(r2_queued, 20, "R2's request queued behind R1")
            assert corridor["holder"] == "R1", corridor
            await r2.synced()
            assert r2.grants() == 0, "the new leader granted the corridor R1 stands in"

            # R1's link comes back, to the process that lives; it is still inside, then leaves.
            await r1.close()
            r1 = await AreaRobot.connect(beta, "R1")
            await r1.report("corridor_e", holding=True)
            await r2.synced()
            assert r2.grants() == 0
            corridor = await _corridor(beta)
            assert (corridor["state"], corridor["holder"]) == ("held", "R1"), corridor
            await r1.report("gb1", holding=False)
            await r2.granted(1, "R2's grant once R1 left the corridor")
            assert (await _corridor(beta))["holder"] == "R2"

            assert await _corridor_events(beta) == [
                ("server_started", {}),  # alpha's life as leader
                ("area_granted", {"robot": "R1", "area": "corridor"}),
                ("server_started", {}),  # beta's
                ("area_granted", {"robot": "R1", "area": "corridor", "restored": True}),
                ("area_released", {"robot": "R1", "area": "corridor", "left": True}),
                ("area_granted", {"robot": "R2", "area": "corridor"}),
            ]
        finally:
            await r1.close()
            await r2.close()


async def _corridor(server: ServerProcess) -> dict[str, Any]:
    async with httpx.AsyncClient(headers=AUTH, timeout=10) as http:
        answer = await http.get(f"{server.url}/api/locks")
    answer.raise_for_status()
    return next(lock for lock in answer.json() if lock["area"] == "corridor")


async def _corridor_events(server: ServerProcess) -> list[tuple[str, dict[str, Any]]]:
    """The event log's lives and the corridor's grants and releases, in order."""
    async with httpx.AsyncClient(headers=AUTH, timeout=10) as http:
        answer = await http.get(f"{server.url}/api/events", params={"limit": 1000})
    answer.raise_for_status()
    kinds = ("area_granted", "area_released", "area_force_released")
    return [
        (e["kind"], {} if e["kind"] == "server_started" else e["data"])
        for e in answer.json()["events"]
        if e["kind"] == "server_started"
        or (e["kind"] in kinds and e["data"].get("area") == "corridor")
    ]
