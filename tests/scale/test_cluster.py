"""Two real server processes on one PostgreSQL database and one redis-server (docs/scaling.md):
messages cross processes; exactly one process leads; a killed leader is replaced."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import Any

import httpx
from click.testing import CliRunner

from backend.server_cli import server as server_command
from bench.cluster_clients import WsClient
from bench.servers import ADMIN_TOKEN, GUI_TOKEN, ServerProcess, wait_until


async def test_messages_cross_processes_both_ways(pair: list[ServerProcess]) -> None:
    alpha, beta = pair
    gui = await WsClient.connect(alpha, GUI_TOKEN)
    robot = await WsClient.connect(beta, "robot-R1-demo-token")  # a follower accepts robots
    admin = await WsClient.connect(alpha, ADMIN_TOKEN, "ops")
    try:
        await gui.send("subscribe", {"patterns": ["say"]})
        await gui.send("ping", {}, id="sync-1")  # once ponged, the subscription is in place
        await wait_until(lambda: _true(gui.of_type("pong")), 10, "pong")
        await robot.send("say", {"text": "welcome to the museum"})
        said = await wait_until(lambda: _true(gui.of_type("say")), 10, "say on the other process")
        assert said[0]["source"] == "R1"
        assert said[0]["payload"]["text"] == "welcome to the museum"
        # Addressed: admin on alpha to the robot connected to beta, not a local name on alpha.
        await admin.send("say", {"text": "to R1 only"}, destination="R1")
        got = await wait_until(lambda: _true(robot.of_type("say")), 10, "addressed message")
        assert got[0]["source"] == "ops" and got[0]["destination"] == "R1"
        await asyncio.sleep(0.5)  # the broker delivers each message once, not echoed back
        assert len(gui.of_type("say")) == 1
        # The leader hears of a robot that connects to, and leaves, a follower.
        await gui.send("subscribe", {"patterns": ["robot_disconnected"]})
        await robot.close()
        gone = await wait_until(
            lambda: _true(gui.of_type("robot_disconnected")), 10, "robot_disconnected"
        )
        assert [m["payload"]["robot"] for m in gone] == ["R1"]
    finally:
        for client in (gui, robot, admin):
            await client.close()


async def test_one_leader_and_fail_over_after_sigkill(pair: list[ServerProcess]) -> None:
    alpha, beta = pair

    async def one_serving() -> list[dict[str, Any]] | None:
        both = [await alpha.health(), await beta.health()]
        serving = all(both) and any(h["cluster"]["serving"] for h in both if h)
        return [h for h in both if h] if serving else None

    first, second = await wait_until(one_serving, 60, "a leader serving")
    leaders = [h for h in (first, second) if h["cluster"]["leading"]]
    assert len(leaders) == 1, (first["cluster"], second["cluster"])
    leader, follower = (alpha, beta) if first["cluster"]["leading"] else (beta, alpha)
    old_epoch = leaders[0]["cluster"]["epoch"]
    assert leaders[0]["components"]["task_manager"]["state"] == "ok"
    standby = await follower.health()
    assert standby is not None
    assert standby["cluster"]["leader"] == leader.name
    assert standby["components"]["task_manager"]["state"] == "disabled"

    async with httpx.AsyncClient(headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}) as http:
        on_follower = await http.get(f"{follower.url}/api/tasks")
        on_leader = await http.get(f"{leader.url}/api/tasks")
    assert on_leader.status_code == 200
    assert on_follower.status_code == 503  # REST runs on the leader; the answer names it
    assert on_follower.json()["leader"] == leader.name

    killed_at = time.monotonic()
    leader.kill()

    async def took_over() -> dict[str, object] | None:
        health = await follower.health()
        ok = health and health["cluster"]["serving"]
        return health if ok else None

    # As long as the follower runs: how long a fail-over takes is `guidebot bench failover`'s
    # measure (tests/scale/test_benches.py), not a bound of this test on a loaded machine.
    health = await follower.until(took_over, "the follower to lead")
    took = time.monotonic() - killed_at
    assert health["cluster"]["leading"] and health["cluster"]["leader"] == follower.name
    assert health["cluster"]["epoch"] == old_epoch + 1
    print(f"fail-over took {took:.2f} s")


def test_broker_needs_postgresql(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        server_command,
        ["--db", f"sqlite+aiosqlite:///{tmp_path}/x.db", "--broker", "redis://127.0.0.1:1"],
    )
    assert result.exit_code == 2
    assert "needs a PostgreSQL" in result.output


def test_a_lease_shorter_than_two_polls_is_refused() -> None:
    result = CliRunner().invoke(
        server_command,
        ["--db", "postgresql+asyncpg://gb@127.0.0.1:1/x", "--broker", "redis://127.0.0.1:1"],
        env={"GUIDEBOT_LEADER_POLL_S": "3", "GUIDEBOT_LEADER_LEASE_S": "5"},
    )
    assert result.exit_code == 2
    assert "GUIDEBOT_LEADER_LEASE_S must be at least twice GUIDEBOT_LEADER_POLL_S" in result.output


async def _true(value: object) -> object:
    return value
