"""The master control end to end: a real server, a real Mosquitto, the simulated vehicle; every
order and instant action the vehicle received is checked against the official schema (the
simulated vehicle refuses what its schema refuses, with an error in its state)."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import aiomqtt
import pytest

from backend.tasks.model import FINAL_STATES, TaskState
from backend.vda5050.order import build_order
from guidebot.payloads.traffic import ReleaseArea, RequestArea
from guidebot.processes import spawn_guidebot
from guidebot.testing import wait_on, wait_until
from guidebot.vda5050.schemas import problems
from guidebot.vda5050.sim import speak_seconds

from .broker import Mosquitto, mosquitto
from .fleet import LINE, V1, Fleet, fleet, vehicle

pytestmark = pytest.mark.timeout(90)


@pytest.fixture
def broker() -> Iterator[Mosquitto]:
    with mosquitto() as b:
        yield b


def released(order: dict) -> list[str]:
    return [n["nodeId"] for n in order["nodes"] if n["released"]]


def all_valid(messages: list[dict], topic: str) -> None:
    for message in messages:
        assert problems(topic, message) == [], message


async def until_done(f: Fleet, task_id: str, timeout: float = 30.0) -> dict:
    state: dict = {}

    def ended() -> bool:
        return any(m.payload.get("task_id") == task_id for m in f.of("task_ended"))

    await wait_on(f.changed, ended, timeout)
    await wait_until(lambda: f.server.app.state.task_manager.tasks[task_id].state in FINAL_STATES)
    state = await f.task_state(task_id)
    return state


async def test_go_to_drives_the_vehicle_through_the_corridor_lock(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        task = await f.task("go_to", {"node": "e"})
        result = await until_done(f, task)
        assert result["state"] == "done", result
        assert sim.last_node == "e"
        # the first order stops before the corridor, granted after: the update extends it
        assert released(sim.orders_received[0]) == ["a", "b"]
        assert sim.orders_received[0]["nodes"][-1]["nodeId"] == "e"  # the rest is horizon
        update = sim.orders_received[-1]
        assert update["orderUpdateId"] >= 1 and update["nodes"][0]["nodeId"] == "b"
        assert released(update)[-1] == "e"
        all_valid(sim.orders_received, "order")
        assert not sim.errors
        reached = [m.payload["node"] for m in f.of("node_reached") if m.source == "V1"]
        assert reached == ["b", "c", "d", "e"]
        grants = [m for m in f.of("area_granted") if m.payload["robot"] == "V1"]
        assert [m.payload["area"] for m in grants] == ["corridor"]
        releases = [m for m in f.of("release_area") if m.source == "V1"]
        assert [m.payload["area"] for m in releases] == ["corridor"]
        traffic = f.server.app.state.traffic
        assert traffic.locks.holder("corridor") is None
        state = f.of("robot_state")[-1].payload
        assert state["robot"] == "V1" and state["node"] == "e" and state["mode"] == "idle"


async def test_the_base_ends_before_an_area_held_by_another_robot(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        other = f.server.app.state.hub.endpoint("R1")
        other.publish(RequestArea(robot="R1", area="corridor"))
        traffic = f.server.app.state.traffic
        await wait_until(lambda: traffic.locks.holder("corridor") == "R1")
        task = await f.task("go_to", {"node": "e"})
        states = f.of("robot_state")
        await wait_on(
            f.changed,
            lambda: (
                any(
                    m.payload["robot"] == "V1" and m.payload["navigation"] == "waiting_area"
                    for m in states
                )
                and sim.last_node == "b"
                and not sim.driving
            ),
            20,
        )
        assert [released(o) for o in sim.orders_received] == [["a", "b"]]
        other.publish(ReleaseArea(robot="R1", area="corridor"))
        result = await until_done(f, task)
        assert result["state"] == "done", result
        assert sim.last_node == "e"
        assert released(sim.orders_received[-1]) == ["b", "c", "d", "e"]
        other.close()


async def test_a_refused_order_fails_the_task_with_the_vehicles_reason(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        sim.reject_orders = "map ground is not loaded"
        task = await f.task("go_to", {"node": "b"})
        result = await until_done(f, task)
        assert result["state"] == "failed", result
        assert "map ground is not loaded" in result["reason"], result
        assert sim.last_node == "a"
        faults = [m.payload for m in f.of("robot_fault") if m.payload["robot"] == "V1"]
        assert faults and faults[0]["kind"] == "vda5050_orderError"


async def test_an_order_never_acknowledged_is_sent_three_times_then_given_up(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        sim.deaf = True
        task = await f.task("go_to", {"node": "b"})
        result = await until_done(f, task, timeout=30)
        assert result["state"] == "failed", result
        assert "never acknowledged" in result["reason"], result
        assert len(sim.orders_ignored) == 3
        assert {o["orderId"] for o in sim.orders_ignored} == {sim.orders_ignored[0]["orderId"]}


async def test_cancel_from_the_console_reaches_the_vehicle(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        sim.speed = 0.05  # slow: still on its way when it is held
        task = await f.task("go_to", {"node": "b"})
        await wait_until(lambda: sim.driving, 10)
        # Held on its way until the cancel comes, however long a loaded machine takes to send it
        # (slow driving alone raced the cancel: the vehicle reached b 8 s after it set off).
        sim.speed = 0.0
        answer = await f.http.post(f"/api/tasks/{task}/cancel", json={"reason": "test"})
        assert answer.status_code == 200, answer.text
        result = await until_done(f, task)
        assert result["state"] == "cancelled", result
        await wait_until(lambda: bool(sim.instant_received), 10)
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        assert "cancelOrder" in kinds
        all_valid(sim.instant_received, "instantActions")
        await wait_until(lambda: not sim.driving and not sim.order.nodes, 10)


@pytest.mark.parametrize("speaks", [True, False], ids=["speech", "no-speech"])
async def test_a_tour_stops_with_an_action_the_factsheet_offers(
    tmp_path: Path, broker: Mosquitto, speaks: bool
) -> None:
    """Each stop is a speak action with the point's text, or, for a vehicle whose factsheet
    offers no speak, a timed wait."""
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        sim.speaks = speaks
        await wait_until(lambda: f.robot("V1").online, 15)
        robot = next(iter(f.master.robots.values()))
        await wait_until(lambda: robot.factsheet is not None, 10)
        assert problems("factsheet", robot.factsheet) == []
        assert robot.speaks is speaks
        task = await f.task("tour", {"tour": "line"})
        result = await until_done(f, task, timeout=60)
        assert result["state"] == "done", result
        progress = [
            (m.payload["index"], m.payload["stage"])
            for m in f.of("tour_progress")
            if m.payload["task_id"] == task
        ]
        assert progress == [(1, "arrived"), (1, "explained"), (2, "arrived"), (2, "explained")]
        # a horizon node comes again in each update, with its actions (same ids)
        stops = list(
            {
                a["actionId"]: a
                for o in sim.orders_received
                for n in o["nodes"]
                for a in n["actions"]
            }.values()
        )
        params = [{p["key"]: p["value"] for p in a["actionParameters"]} for a in stops]
        if speaks:
            assert [a["actionType"] for a in stops] == ["speak", "speak"]
            assert [p["text"] for p in params] == ["Here is the bee.", "The end of the line."]
        else:
            assert [a["actionType"] for a in stops] == ["wait", "wait"]
            assert [p["seconds"] for p in params] == [
                speak_seconds("Here is the bee."),
                speak_seconds("The end of the line."),
            ]
        assert all(sim.actions[a["actionId"]].status == "FINISHED" for a in stops)
        all_valid(sim.orders_received, "order")


async def test_a_bad_message_is_logged_counted_and_alerted_and_nothing_is_lost(
    tmp_path: Path, broker: Mosquitto, caplog: pytest.LogCaptureFixture
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        async with aiomqtt.Client("127.0.0.1", broker.port) as client:
            await client.publish(V1.topic("state"), b"{not json", qos=1)
            bad = sim.state() | {"batteryState": {"batteryCharge": "full"}}
            await client.publish(V1.topic("state"), json.dumps(bad), qos=1)
        await wait_until(lambda: f.master.refused == 2, 10)
        alerts = f.server.app.state.alerts
        alert = alerts.get("vda5050_message", "V1")
        assert alert is not None and alert.count == 2
        assert "batteryState/batteryCharge" in alert.message
        assert "V1: message on uagv/v2/Acme/sn-0001/state ignored" in caplog.text
        # the vehicle goes on: a task after it is done
        task = await f.task("go_to", {"node": "b"})
        result = await until_done(f, task)
        assert result["state"] == "done", result
        assert f.robot("V1").online


async def test_the_broker_down_at_start_and_coming_back(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    with mosquitto(started=False) as broker:
        async with fleet(tmp_path, broker.url) as f:
            alerts = f.server.app.state.alerts
            await wait_until(lambda: alerts.is_active("vda5050_broker", broker.url), 10)
            assert f"cannot reach the MQTT broker {broker.url}" in caplog.text
            broker.start()
            async with vehicle(broker.url) as sim:
                await wait_until(lambda: f.robot("V1").online, 30)
                assert not alerts.is_active("vda5050_broker", broker.url)
                # the broker goes and comes back: the master reconnects by itself
                broker.stop()
                await wait_until(lambda: alerts.is_active("vda5050_broker", broker.url), 10)
                broker.start()
                await wait_until(lambda: f.master.session.connections == 2, 30)
                task = await f.task("go_to", {"node": "b"})
                result = await until_done(f, task, timeout=40)
                assert result["state"] == "done", result
                assert sim.last_node == "b"


async def test_a_broken_connection_is_a_robot_disconnected(
    tmp_path: Path, broker: Mosquitto
) -> None:
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        async with aiomqtt.Client("127.0.0.1", broker.port) as client:
            # what the broker publishes for the vehicle's last will
            will = {**V1.header(7), "connectionState": "CONNECTIONBROKEN"}
            await client.publish(V1.topic("connection"), json.dumps(will), qos=1)
        await wait_on(
            f.changed,
            lambda: any(m.payload["robot"] == "V1" for m in f.of("robot_disconnected")),
            10,
        )
        assert sim.session.connected.is_set()


async def test_a_low_battery_sends_the_vehicle_to_charge(tmp_path: Path, broker: Mosquitto) -> None:
    dock = [{"id": "dock", "node": "a"}]
    async with fleet(tmp_path, broker.url, charging_stations=dock) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        sim.x = 4.0  # at b: the dock is at a
        sim.last_node = "b"
        await wait_until(lambda: f.robot("V1").node == "b", 10)
        sim.battery = 0.25  # below the robot's battery_low (0.3)
        await wait_on(
            f.changed, lambda: any(m.payload["robot"] == "V1" for m in f.of("battery_low")), 10
        )
        await wait_until(lambda: sim.charging, 30)
        assert sim.last_node == "a"
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        assert "startCharging" in kinds
        await wait_on(
            f.changed,
            lambda: f.of("robot_state")[-1].payload["mode"] == "charging",
            10,
        )


async def test_a_vehicle_process_killed_mid_order_loses_its_task_after_the_grace_period(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """A real `guidebot vda5050-sim` process, killed (SIGKILL) on its way: the broker sends its
    last will (CONNECTIONBROKEN), the robot is disconnected, and after the grace period its
    task goes back to the queue."""
    async with fleet(tmp_path, broker.url) as f:
        tm = f.server.app.state.task_manager
        tm.lost_grace_s = 1.0
        args = ["vda5050-sim", "--broker", broker.url, "--manufacturer", V1.manufacturer]
        args += ["--serial-number", V1.serial_number, "--map-id", "ground", "--node", "a"]
        args += ["--speed", "0.1", "--state-period", "0.2"]
        process = spawn_guidebot(args)
        try:
            await wait_until(lambda: f.robot("V1").online, 30)
            task = await f.task("go_to", {"node": "e"})
            await wait_on(
                f.changed,
                lambda: any(
                    m.payload["robot"] == "V1" and m.payload["navigation"] == "moving"
                    for m in f.of("robot_state")
                ),
                20,
            )
        finally:
            process.kill()
            process.wait(10)
        await wait_on(
            f.changed,
            lambda: any(m.payload["robot"] == "V1" for m in f.of("robot_disconnected")),
            20,
        )
        await wait_until(lambda: tm.tasks[task].state == TaskState.QUEUED, 20)
        history = (await f.http.get(f"/api/tasks/{task}/history")).json()
        assert "robot lost" in str(history), history


async def test_a_vehicle_on_an_order_of_another_master_is_cancelled_first(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """As after a restart of the server: the vehicle still drives an order this master did
    not give; a new task stops it with cancelOrder, then sends its own order."""
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        await wait_until(lambda: f.robot("V1").online, 15)
        sim.speed = 0.02  # crawls: still on the old order when the task comes
        steps = [{"node": n, "floor": "F0", "x": 4.0 * i, "y": 0.0} for i, n in enumerate(LINE[:3])]
        old = build_order(
            V1, 0, "old-order", 0, steps, start=0, released_to=2, map_ids={"F0": "ground"}
        )
        async with aiomqtt.Client("127.0.0.1", broker.port) as client:
            await client.publish(V1.topic("order"), json.dumps(old), qos=1)
        robot = next(iter(f.master.robots.values()))
        await wait_until(lambda: (robot.state or {}).get("orderId") == "old-order", 10)
        sim.speed = 1.0
        task = await f.task("go_to", {"node": "a"})
        result = await until_done(f, task)
        assert result["state"] == "done", result
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        assert "cancelOrder" in kinds
        assert sim.order.order_id.startswith(task) and sim.last_node == "a"
