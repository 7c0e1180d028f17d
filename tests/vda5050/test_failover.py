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
from building_sim.simulator import BuildingSimulator
from guidebot.site.building_config import load_building
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


async def _go_to_d(leader: ServerProcess) -> str:
    """Once V1 is online on ``leader``: a go-to d pinned to it; its task id."""

    async def v1_online() -> bool:
        robots = await _get(leader, "/api/robots") or []
        return any(r["name"] == "V1" and r.get("online") for r in robots)

    await poll(v1_online, 30, f"V1 online on {leader.name}")
    async with httpx.AsyncClient(headers=AUTH, timeout=10) as http:
        created = await http.post(
            f"{leader.url}/api/tasks",
            json={"kind": "go_to", "params": {"node": "d"}, "robot": "V1"},
        )
    assert created.status_code == 201, created.text
    return str(created.json()["id"])


async def _until_done(leader: ServerProcess, task_id: str) -> None:
    """Until ``task_id`` is done under ``leader`` (failed or cancelled: the test fails)."""

    async def done() -> dict[str, Any] | None:
        task = await _get(leader, f"/api/tasks/{task_id}") or {}
        assert task.get("state") not in ("failed", "cancelled"), task
        return task if task.get("state") == "done" else None

    await poll(done, 60, f"the go-to to end under {leader.name}")


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
            task_id = await _go_to_d(alpha)
            # its base ends at b: the corridor is R1's
            await wait_until(lambda: sim.last_node == "b" and not sim.driving, 30)
            assert [n["nodeId"] for n in sim.order.nodes if n["released"]] == []
            alpha.kill()
            await poll(lambda: _serving(beta), 30, "beta to lead", 0.05)
            await r1.report("e", True)
            await r1.release()
            await _until_done(beta, task_id)
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


def door_site() -> dict[str, Any]:
    """The line with door_b on b, on one Modbus module (its port set once the simulator runs)."""
    site = site_dict(
        modules=[
            {
                "id": "m1",
                "port": 1,
                "points": [
                    {"name": "door_b_open", "address": 0, "kind": "coil", "node": "b"},
                    {"name": "door_b_is_open", "address": 0, "kind": "discrete_input", "node": "b"},
                ],
            }
        ],
        doors=[
            {
                "id": "door_b",
                "node": "b",
                "open": {"module": "m1", "point": "door_b_open"},
                "is_open": {"module": "m1", "point": "door_b_is_open"},
                "open_time_s": 1.0,
            }
        ],
    )
    for robot in site["robots"]:
        if robot["name"] == "R1":
            robot["token"] = ROBOT_TOKENS["R1"]
    return site


async def test_a_new_leader_lets_go_on_a_vehicle_the_old_one_paused_for_a_door(
    tmp_path: Path, broker: Mosquitto, postgres: PostgresServer, redis: RedisServer
) -> None:
    """The leader's master paused V1 before door_b (the door's module went offline: the door
    counts as closed, and the master's open_door is refused) when the leader is SIGKILLed. The
    new leader found V1 paused and could not tell the old master's pause from staff's: V1 stayed
    paused until staff let it go on. The pause's owner is in the event log (PostgreSQL), so the
    new master lets V1 go on once the building answers its open_door, and the go-to ends done."""
    site = door_site()
    config = load_building(site)
    async with BuildingSimulator(config, time_scale=10.0, port_zero=True) as building:
        site["modules"][0]["port"] = building.ports["m1"]
        site_file = tmp_path / "site.yaml"
        site_file.write_text(yaml.safe_dump(site, sort_keys=False), encoding="utf-8")
        env = {"GUIDEBOT_MQTT_URL": broker.url, "GUIDEBOT_BUILDING_ENABLED": "true"}
        async with (
            start_servers(
                ["alpha", "beta"], postgres.database(), redis.url, tmp_path, site=site_file, env=env
            ) as (alpha, beta),
            vehicle(broker.url) as sim,
        ):
            sim.speed = 0.1  # 4 s of wall time from a to b
            await poll(lambda: _serving(alpha), 60, "alpha to lead")
            task_id = await _go_to_d(alpha)
            # door_b opened for V1: its base goes through b; the module drops before V1 is there
            await wait_until(lambda: any(n["nodeId"] == "b" for n in sim.order.nodes), 30)
            await wait_until(lambda: sim.order.nodes[0]["released"] and sim.driving, 30)
            await building.set_fault("m1", "offline")
            await wait_until(lambda: sim.paused and not sim.driving, 15)
            assert sim.last_node == "a"

            async def pause_logged() -> bool:
                events = await _get(alpha, "/api/events?kind=vda5050_pause&latest=true") or {}
                return any(e["data"].get("paused") for e in events.get("events", []))

            await poll(pause_logged, 15, "the master's pause in the event log")
            alpha.kill()
            await building.set_fault("m1", "none")
            await poll(lambda: _serving(beta), 30, "beta to lead", 0.05)
            await _until_done(beta, task_id)
        assert sim.last_node == "d" and not sim.paused and not sim.errors
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        assert [k for k in kinds if k.endswith("Pause")][-1] == "stopPause", kinds
        assert "cancelOrder" not in kinds, kinds
