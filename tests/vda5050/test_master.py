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
from backend.vda5050 import vehicle as vehicle_module
from backend.vda5050.order import build_order
from guidebot.payloads.traffic import ReleaseArea, RequestArea
from guidebot.processes import spawn_guidebot
from guidebot.testing import wait_on, wait_until
from guidebot.vda5050.schemas import problems
from guidebot.vda5050.sim import SimVehicle, speak_seconds
from guidebot.vda5050.topics import Vehicle, parse_broker
from tests.promtool import promtool_accepts

from .broker import Mosquitto, mosquitto
from .fleet import LINE, V1, Fleet, fleet, site_dict, vehicle

pytestmark = pytest.mark.timeout(90)

V2 = Vehicle(manufacturer="Acme", serial_number="sn-0002")


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

        def kinds() -> list[str]:
            return [a["actionType"] for m in sim.instant_received for a in m["actions"]]

        # Other instant actions may come first (a stateRequest and a factsheetRequest when the
        # vehicle's connection comes back, as it did on a loaded machine): wait for the cancel.
        await wait_until(lambda: "cancelOrder" in kinds(), 10)
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
        # From its start the tour says where it is, as a GuideBot robot's does: "on the way
        # to stop 1 of 2" (the vehicle starts it within the assignment, before the server
        # has recorded it as assigned).
        started = next(
            m.payload
            for m in f.of("task_event")
            if m.payload["task_id"] == task and m.payload["state"] == "running"
        )
        assert started["progress"] == {
            "index": 0,
            "total": 2,
            "poi": None,
            "name": None,
            "stage": "assigned",
            "skipped": [],
        }
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
        scrape = (await f.http.get("/metrics")).text
        assert 'guidebot_vda5050_messages_refused_total{robot="V1"} 2.0' in scrape
        await promtool_accepts(scrape)
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


async def test_a_low_battery_sends_the_vehicle_to_charge_until_it_is_full(
    tmp_path: Path, broker: Mosquitto
) -> None:
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
        tm = f.server.app.state.task_manager
        (charge,) = [t for t in tm.tasks.values() if t.kind == "charge" and t.robot == "V1"]
        assert charge.state == TaskState.RUNNING  # not over when charging starts
        sim.battery = 0.94  # nearly full: the rest at the simulated charger's pace
        await wait_until(lambda: charge.state in FINAL_STATES, 30)
        assert charge.state == TaskState.DONE and sim.battery >= 0.95
        # The task ends as stopCharging is sent; the vehicle acts on it a moment later.
        await wait_until(lambda: not sim.charging, 10)
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        charging = [k for k in kinds if k in ("startCharging", "stopCharging")]
        assert charging[-2:] == ["startCharging", "stopCharging"], kinds


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


async def test_a_vehicle_back_within_the_grace_period_is_planned_again_from_where_it_stands(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """The vehicle waits at b for the corridor, goes away (its process stops), is pushed back
    to a by hand and comes back restarted there without its order, within the grace period:
    the master control plans the drive again from a with a new order, instead of extending
    the lost one from b, which the vehicle would refuse (it is not at b)."""
    async with fleet(tmp_path, broker.url) as f:
        other = f.server.app.state.hub.endpoint("R1")
        other.publish(RequestArea(robot="R1", area="corridor"))
        traffic = f.server.app.state.traffic
        await wait_until(lambda: traffic.locks.holder("corridor") == "R1")
        async with vehicle(broker.url) as first:
            await wait_until(lambda: f.robot("V1").online, 15)
            task = await f.task("go_to", {"node": "e"})
            await wait_until(lambda: first.last_node == "b" and not first.driving, 20)
        await wait_until(lambda: not f.robot("V1").online, 15)
        async with vehicle(broker.url) as again:  # restarted at a
            await wait_until(lambda: f.robot("V1").online, 15)
            await wait_until(lambda: f.robot("V1").node == "a", 15)
            other.publish(ReleaseArea(robot="R1", area="corridor"))
            result = await until_done(f, task)
        other.close()
        assert result["state"] == "done", result
        assert again.last_node == "e" and not again.errors
        sent = [(o["orderId"], o["nodes"][0]["nodeId"]) for o in again.orders_received]
        assert sent and sent[0] == (f"{task}-2", "a"), sent
        all_valid(again.orders_received, "order")
        history = (await f.http.get(f"/api/tasks/{task}/history")).json()
        events = [h["event"] for h in history]
        assert events.count("assigned") == 1 and "requeued" not in events, history


async def test_a_late_state_after_a_broken_connection_is_not_taken_for_a_lost_order(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """Under load, after MQTT connections broke, V1's tour failed "order refused: still
    driving an order" (or "not at hall"): the vehicle's connection broke (its last will) and
    the broker then delivered a state it had sent before it took its current order, naming the
    tour's first order at b. The master took it for a lost order and sent a new one from b
    while the vehicle drove on to e. A state older than the last one (an earlier order of the
    task, an earlier update) is ignored: the tour goes on with its order and ends done."""
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        sim.speed = 0.1  # 4 s of wall time per edge
        await wait_until(lambda: f.robot("V1").online, 15)
        tour = await f.task("tour", {"tour": "line"})
        await wait_until(lambda: sim.order.order_id == f"{tour}-2" and sim.last_node == "c", 40)
        late = sim.state() | {
            "headerId": 0,
            "orderId": f"{tour}-1",
            "orderUpdateId": 0,
            "lastNodeId": "b",
            "lastNodeSequenceId": 2,
            "nodeStates": [],
            "edgeStates": [],
            "driving": False,
        }
        async with aiomqtt.Client("127.0.0.1", broker.port) as client:
            will = {**V1.header(7), "connectionState": "CONNECTIONBROKEN"}
            await client.publish(V1.topic("connection"), json.dumps(will), qos=1)
            await client.publish(V1.topic("state"), json.dumps(late), qos=1)
        result = await until_done(f, tour, 60)
        assert result["state"] == "done", result
        assert sim.last_node == "e"
        sent = sorted({o["orderId"] for o in sim.orders_received})
        assert sent == [f"{tour}-1", f"{tour}-2"], sent
        all_valid(sim.orders_received, "order")


async def test_an_update_due_while_the_broker_is_down_is_sent_once_it_is_back(
    tmp_path: Path, broker: Mosquitto, monkeypatch: pytest.MonkeyPatch
) -> None:
    """V1 waits at b for the corridor R1 holds; the broker dies, and R1 lets the corridor go
    meanwhile: the update that releases it cannot leave. Each send the broker never took was
    counted as one of the order's three tries, and the task failed "never acknowledged" before
    the broker was back. Then the broker is back before the vehicle (its own reconnection has
    a back-off; here it hangs until let go): the sends the broker took while the vehicle could
    not hear them were counted too (a clean run failed so). Only sends the vehicle could hear
    count: the update goes once both are back, and the task ends done."""
    monkeypatch.setattr(vehicle_module, "ACK_TIMEOUT_S", 1.0)  # three tries within 3 s
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        other = f.server.app.state.hub.endpoint("R1")
        other.publish(RequestArea(robot="R1", area="corridor"))
        traffic = f.server.app.state.traffic
        await wait_until(lambda: traffic.locks.holder("corridor") == "R1")
        await wait_until(lambda: f.robot("V1").online, 15)
        session = f.master.session
        unsent: list[str] = []
        sent: list[str] = []
        publish = session.publish

        async def counted(topic: str, message: dict, **options: bool) -> bool:
            went = await publish(topic, message, **options)
            if topic.endswith("/order"):
                (sent if went else unsent).append(str(message["orderUpdateId"]))
            return went

        session.publish = counted
        task = await f.task("go_to", {"node": "e"})
        await wait_until(lambda: sim.last_node == "b" and not sim.driving, 20)
        broker.stop()
        await wait_until(lambda: not session.connected.is_set(), 15)
        other.publish(ReleaseArea(robot="R1", area="corridor"))
        await wait_until(lambda: len(unsent) > vehicle_module.ORDER_TRIES, 20)
        assert (await f.task_state(task))["state"] == "running"
        sim.hung = True
        before = len(sent)
        broker.start()
        await wait_until(lambda: len(sent) > before + vehicle_module.ORDER_TRIES, 30)
        assert (await f.task_state(task))["state"] == "running"
        sim.hung = False
        result = await until_done(f, task, 60)
        other.close()
        assert result["state"] == "done", result
        assert sim.last_node == "e" and not sim.errors
        all_valid(sim.orders_received, "order")


async def test_a_vehicle_silent_without_a_last_will_is_disconnected_until_it_speaks(
    tmp_path: Path, broker: Mosquitto, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A vehicle whose software hangs stays connected to the broker, so no last will comes: the
    master took it for online for ever (a task on it waited with it). Silent for ``SILENCE_S``,
    it is disconnected (the Task Manager's grace period follows); its next state brings it
    back."""
    monkeypatch.setattr(vehicle_module, "SILENCE_S", 2.0)
    tm = None
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as sim:
        tm = f.server.app.state.task_manager
        await wait_until(lambda: f.robot("V1").online and tm.robots["V1"].online, 15)
        sim.hung = True
        await wait_on(
            f.changed,
            lambda: any(m.payload["robot"] == "V1" for m in f.of("robot_disconnected")),
            20,
        )
        assert sim.session.connected.is_set()
        await wait_until(lambda: not tm.robots["V1"].online, 10)
        connected = len(f.of("robot_connected"))
        sim.hung = False
        await wait_on(f.changed, lambda: len(f.of("robot_connected")) > connected, 20)
        await wait_until(lambda: tm.robots["V1"].online, 10)


async def test_a_site_edit_reaches_the_master_control_without_a_restart(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """A published site adds vehicle V2: it joins (online, a task done) and V1 goes on; one
    that changes an area only reaches the same master control."""
    async with fleet(tmp_path, broker.url) as f, vehicle(broker.url) as v1:
        await wait_until(lambda: f.robot("V1").online, 15)
        site = site_dict()
        site["robots"].append(
            {
                "name": "V2",
                "token": "robot-V2-test-token",
                "start_node": "b",
                "interface": "vda5050",
                "manufacturer": V2.manufacturer,
                "serial_number": V2.serial_number,
                "map_ids": {"F0": "ground"},
            }
        )
        answer = await f.http.put("/api/site", json=site)
        assert answer.status_code == 200, answer.text
        v2 = SimVehicle(
            parse_broker(broker.url),
            V2,
            x=4.0,
            map_id="ground",
            node="b",
            time_scale=10.0,
            state_period_s=0.2,
        )
        async with v2:
            await wait_until(lambda: "V2" in f.server.app.state.task_manager.robots, 15)
            await wait_until(lambda: f.robot("V2").online, 15)
            answer = await f.http.post(
                "/api/tasks", json={"kind": "go_to", "params": {"node": "e"}, "robot": "V2"}
            )
            assert answer.status_code == 201, answer.text
            result = await until_done(f, answer.json()["id"])
            assert result["state"] == "done" and v2.last_node == "e", result
            task = await f.task("go_to", {"node": "b"})
            result = await until_done(f, task)
            assert result["robot"] == "V1" and result["state"] == "done" and v1.last_node == "b"
            # the same robots, a smaller corridor: the same master control, the new area
            master = f.master
            site["areas"] = [{"id": "corridor", "nodes": ["c"]}]
            answer = await f.http.put("/api/site", json=site)
            assert answer.status_code == 200, answer.text
            assert f.master is master
            robot = next(r for r in master.robots.values() if r.name == "V1")
            assert robot.area_nodes["corridor"] == {"c"}
        all_valid(v2.orders_received, "order")


async def test_a_visitors_tour_preempts_an_errand_without_a_refusal(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """V1 on its idle errand (to the wait point at e) when a visitor asks for a tour: the
    Task Manager cancels the errand and assigns the tour at once; the vehicle ends the errand
    (cancelOrder) and then takes the tour, instead of refusing it as busy."""
    wait = [{"id": "rest", "node": "e"}]
    async with (
        fleet(tmp_path, broker.url, wait_points=wait) as f,
        vehicle(broker.url) as sim,
    ):
        sim.speed = 0.2  # still on its errand when the visitor asks
        tm = f.server.app.state.task_manager
        await wait_until(lambda: f.robot("V1").online, 15)
        await wait_until(lambda: sim.driving, 20)
        (errand,) = [t for t in tm.tasks.values() if t.robot == "V1" and t.internal]
        sim.speed = 1.0
        tour = await f.task("tour", {"tour": "line"})
        result = await until_done(f, tour, 60)
        assert result["state"] == "done", result
        assert errand.state == TaskState.CANCELLED
        history = (await f.http.get(f"/api/tasks/{tour}/history")).json()
        events = [h["event"] for h in history]
        assert events.count("assigned") == 1 and "requeued" not in events, history
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        assert "cancelOrder" in kinds


async def test_a_restarted_server_goes_on_with_the_tour_the_vehicle_runs(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """The server stops while V1 drives to the tour's second stop (the first explained); the
    next server life finds the vehicle on that order and goes on with it: the tour ends
    done, assigned once, the second stop explained, nothing cancelled or sent twice."""
    async with vehicle(broker.url) as sim:
        sim.speed = 0.1  # slow: still on its way to e while the server restarts
        async with fleet(tmp_path, broker.url) as f:
            await wait_until(lambda: f.robot("V1").online, 15)
            tour = await f.task("tour", {"tour": "line"})
            await wait_until(lambda: sim.last_node == "c", 30)
        async with fleet(tmp_path, broker.url) as f:
            result = await until_done(f, tour, 60)
            assert result["state"] == "done", result
            explained = [
                m.payload["index"]
                for m in f.of("tour_progress")
                if m.payload["stage"] == "explained"
            ]
            assert explained == [2], explained
            history = (await f.http.get(f"/api/tasks/{tour}/history")).json()
        events = [h["event"] for h in history]
        assert events.count("assigned") == 1 and "requeued" not in events, history
        assert sim.last_node == "e"
        sent = [(o["orderId"], o["orderUpdateId"]) for o in sim.orders_received]
        assert len(sent) == len(set(sent)) and all(o.startswith(f"{tour}-") for o, _ in sent)
        kinds = [a["actionType"] for m in sim.instant_received for a in m["actions"]]
        assert "cancelOrder" not in kinds, kinds
        all_valid(sim.orders_received, "order")
