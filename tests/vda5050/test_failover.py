"""Fail-over with a VDA 5050 vehicle (issue 37, docs/vda5050.md "Several server processes"):
two real `guidebot server --broker` processes on one PostgreSQL and one redis-server, a real
Mosquitto, the simulated vehicle. Only the leader runs the master control; the leader is
SIGKILLed while its vehicle waits at the end of its base for the corridor another robot holds.
The new leader goes on with the same order: the grant is an update of it (the next
``orderUpdateId``, stitched at the base's end), nothing is cancelled or sent twice, and the task
ends done, assigned once."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from bench.cluster_clients import ROBOT_TOKENS, AreaRobot
from bench.servers import ADMIN_TOKEN, ServerProcess, start_servers
from bench.servers import wait_until as poll
from guidebot.testing import wait_until
from guidebot.vda5050.schemas import problems
from tests.scale.redis import RedisServer, redis_server
from tests.server.postgres import PostgresServer, postgres_server

from .broker import Mosquitto, mosquitto
from .fleet import site_dict, vehicle

pytestmark = pytest.mark.timeout(150)

AUTH = {"Authorization": f"Bearer {ADMIN_TOKEN}"}


@pytest.fixture
def broker() -> Iterator[Mosquitto]:
    with mosquitto() as b:
        yield b


@pytest.fixture(scope="module")
def redis() -> Iterator[RedisServer]:
    with redis_server() as server:
        yield server


@pytest.fixture(scope="module")
def postgres() -> Iterator[PostgresServer]:
    with postgres_server() as pg:
        yield pg


async def _get(server: ServerProcess, path: str) -> Any:
    async with httpx.AsyncClient(headers=AUTH, timeout=10) as http:
        answer = await http.get(f"{server.url}{path}")
    return answer.json() if answer.status_code == 200 else None


async def _serving(server: ServerProcess) -> bool:
    health = await server.health()
    return bool(health and health["cluster"]["serving"])


async def test_a_new_leader_goes_on_with_the_vehicles_order(
    tmp_path: Path, broker: Mosquitto, postgres: PostgresServer, redis: RedisServer
) -> None:
    site = site_dict()
    for robot in site["robots"]:
        if robot["name"] == "R1":
            robot["token"] = ROBOT_TOKENS["R1"]  # the token bench's AreaRobot signs in with
    site_file = tmp_path / "site.yaml"
    site_file.write_text(yaml.safe_dump(site, sort_keys=False), encoding="utf-8")
    env = {"GUIDEBOT_MQTT_URL": broker.url}
    async with (
        start_servers(
            ["alpha", "beta"], postgres.database(), redis.url, tmp_path, site=site_file, env=env
        ) as (alpha, beta),
        vehicle(broker.url) as sim,
    ):
        await poll(lambda: _serving(alpha), 60, "alpha to lead")
        r1 = await AreaRobot.connect(beta, "R1")  # on the process that survives
        try:
            await r1.report("e", False)
            await r1.ask()
            await r1.granted(1, "R1's corridor")

            async def v1_online() -> bool:
                robots = await _get(alpha, "/api/robots") or []
                return any(r["name"] == "V1" and r.get("online") for r in robots)

            await poll(v1_online, 30, "V1 online on alpha")
            async with httpx.AsyncClient(headers=AUTH, timeout=10) as http:
                created = await http.post(
                    f"{alpha.url}/api/tasks",
                    json={"kind": "go_to", "params": {"node": "d"}, "robot": "V1"},
                )
            assert created.status_code == 201, created.text
            task_id = created.json()["id"]
            # its base ends at b: the corridor is R1's
            await wait_until(lambda: sim.last_node == "b" and not sim.driving, 30)
            assert [n["nodeId"] for n in sim.order.nodes if n["released"]] == []
            alpha.kill()
            await poll(lambda: _serving(beta), 30, "beta to lead", 0.05)
            await r1.report("e", True)
            await r1.release()

            async def done() -> dict[str, Any] | None:
                task = await _get(beta, f"/api/tasks/{task_id}") or {}
                assert task.get("state") not in ("failed", "cancelled"), task
                return task if task.get("state") == "done" else None

            await poll(done, 60, "the go-to to end under beta")
        finally:
            await r1.close()
        assert sim.last_node == "d"
        order = f"{task_id}-1"
        sent = [(o["orderId"], o["orderUpdateId"]) for o in sim.orders_received]
        assert sent == [(order, 0), (order, 1)], sent
        update = sim.orders_received[1]
        assert (update["nodes"][0]["nodeId"], update["nodes"][0]["sequenceId"]) == ("b", 2)
        assert [n["nodeId"] for n in update["nodes"] if n["released"]] == ["b", "c", "d"]
        for message in sim.orders_received:
            assert problems("order", message) == [], message
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        assert "cancelOrder" not in kinds, kinds
        assert not sim.errors
        history = await _get(beta, f"/api/tasks/{task_id}/history")
        events = [h["event"] for h in history]
        assert events.count("assigned") == 1, history
        assert not {"requeued", "reassigned"} & set(events), history
