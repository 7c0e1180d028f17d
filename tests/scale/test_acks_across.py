"""A robot's must-arrive messages across processes (docs/protocol.md "Delivery guarantee",
docs/scaling.md): the hub acknowledges one once the deciding components have handled it, so a
robot on a follower is acknowledged by the leader, through the broker. While no process
decides (a fail-over) nothing is acknowledged: the robot's link sends the message again, and
the new leader handles it. Copies are handled once. A task_ended sent again that comes after
the robot_state no longer naming the task still ends it (docs/server.md, "After a restart")."""

from __future__ import annotations

import asyncio
import itertools
from typing import Any

import httpx

from backend.cluster import LOST_LEADERSHIP_EXIT
from bench.cluster_clients import AREA, ROBOT_TOKENS, AreaRobot, WsClient
from bench.servers import ADMIN_TOKEN, ServerProcess, wait_until

AUTH = {"Authorization": f"Bearer {ADMIN_TOKEN}"}

_ids = itertools.count()


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
    await alpha.until(alpha.leads, "alpha to lead")
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
    await alpha.until(alpha.leads, "alpha to lead")
    r1 = await AreaRobot.connect(beta, "R1")
    try:
        alpha.pause()  # the leader decides nothing now; beta leads after alpha's lease
        try:
            asked = f"ask-{next(_ids)}"
            await _send(r1, "request_area", asked)
            await asyncio.sleep(0.5)
            assert not await beta.leads(), "beta led too soon for this test"
            assert _acks(r1, asked) == [], "a follower acknowledged what nobody handled"
            await beta.until(beta.leads, "beta to lead after alpha's lease")
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


async def test_a_task_ended_during_a_fail_over_is_not_run_again(
    pair: list[ServerProcess],
) -> None:
    """R1 ends its task while no process decides. Its link sends task_ended again (no ack) on
    its back-off, and its robot_state, which no longer names the task, may reach the new
    leader first: the task must end done, not go back to the queue and to R1 a second time."""
    alpha, beta = pair
    await alpha.until(alpha.leads, "alpha to lead")
    r1 = await WsClient.connect(beta, ROBOT_TOKENS["R1"])
    try:
        await _state(r1, None)
        async with httpx.AsyncClient(headers=AUTH, timeout=10) as http:
            created = await http.post(
                f"{alpha.url}/api/tasks",
                json={"kind": "go_to_poi", "params": {"poi": "welcome"}, "robot": "R1"},
            )
        assert created.status_code == 201, created.text
        task_id = created.json()["id"]
        assigned = await wait_until(lambda: _true(_assigned(r1, task_id)), 20, "task_assigned")
        await r1.send("ack", {"message_id": assigned[0]["id"]}, destination="task_manager")
        await r1.send("task_started", {"task_id": task_id, "robot": "R1"}, id=f"s-{task_id}")
        await _state(r1, task_id)
        await wait_until(lambda: _task_state(alpha, task_id, "running"), 20, "the task running")

        alpha.pause()
        try:
            ended = f"e-{task_id}"
            await r1.send("task_ended", {"task_id": task_id, "robot": "R1"}, id=ended)
            await beta.until(beta.leads, "beta to lead after alpha's lease")
            await _state(r1, None)  # its state, at its steady rate, comes first
            await r1.send("task_ended", {"task_id": task_id, "robot": "R1"}, id=ended)
            await wait_until(lambda: _task_state(beta, task_id, "done"), 20, "the task done")
        finally:
            alpha.resume()
        assert await asyncio.to_thread(alpha.process.wait, 30) == LOST_LEADERSHIP_EXIT
        async with httpx.AsyncClient(headers=AUTH, timeout=10) as http:
            history = (await http.get(f"{beta.url}/api/tasks/{task_id}/history")).json()
        events = [h["event"] for h in history]
        assert events.count("assigned") == 1 and "requeued" not in events, history
        assert len(_assigned(r1, task_id)) == 1, "the task was sent to R1 a second time"
    finally:
        await r1.close()


def _assigned(robot: WsClient, task_id: str) -> list[dict[str, Any]]:
    return [m for m in robot.of_type("task_assigned") if m["payload"]["task_id"] == task_id]


async def _state(robot: WsClient, task_id: str | None) -> None:
    payload = {"robot": "R1", "node": "hall", "mode": "busy" if task_id else "idle"}
    await robot.send("robot_state", {**payload, "task_id": task_id})
    ping = f"state-{next(_ids)}"
    await robot.send("ping", {}, id=ping)
    await wait_until(
        lambda: _true(any(m.get("correlation_id") == ping for m in robot.of_type("pong"))),
        20,
        "pong",
    )


async def _task_state(server: ServerProcess, task_id: str, state: str) -> bool:
    async with httpx.AsyncClient(headers=AUTH, timeout=10) as http:
        answer = await http.get(f"{server.url}/api/tasks/{task_id}")
    return answer.status_code == 200 and answer.json()["state"] == state
