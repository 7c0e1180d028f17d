"""Task Manager over a real bus with scripted robots: the life of tasks, priorities, battery
alarms, robot loss, reassignment, idle robots and reconciliation after a restart."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest

from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.site.service import SiteService
from backend.tasks import Task, TaskError, TaskManager, TaskState
from guidebot.bus import Bus
from guidebot.messages import Message
from guidebot.site import validate_site

from .conftest import Clock
from .helpers import RobotStub, demo_site


def fleet(bus: Bus) -> tuple[RobotStub, RobotStub, RobotStub]:
    """Three robots at home (two stations and the wait point), online and idle."""
    robots = (
        RobotStub(bus, "R1", "charge_a"),
        RobotStub(bus, "R2", "charge_b"),
        RobotStub(bus, "R3", "entrance"),
    )
    for robot in robots:
        robot.state()
    return robots


def assigned(robot: RobotStub, net: str | None = None) -> list[Message]:
    return [m for m in robot.of_type("task_assigned") if net is None or m.payload["net"] == net]


def states_of(events: list[Message], task_id: str) -> list[str]:
    return [m.payload["state"] for m in events if m.payload["task_id"] == task_id]


async def test_full_life_of_a_tour(bus: Bus, manager: TaskManager, events: list[Message]) -> None:
    r1, r2, r3 = fleet(bus)
    task = manager.request("tour", {"tour": "ground"}, requester="panel-1")
    order = await r3.wait_for("task_assigned")  # nearest to the first point (the hall)
    assert order.payload["net"] == "give_tour"
    params = order.payload["params"]
    assert params["tour"] == "ground"
    assert [p["poi"] for p in params["points"]] == [
        "welcome",
        "mosaics",
        "amphorae",
        "sword",
        "loom",
    ]
    assert (
        params["points"][2]["media"] == ["demo_museum/amphorae.svg"] and params["points"][0]["text"]
    )
    r3.start(task.id)
    assert task.state is TaskState.RUNNING
    r3.end(task.id)
    assert task.state is TaskState.DONE
    assert states_of(events, task.id) == ["queued", "assigned", "running", "done"]
    assert not assigned(r1) and not assigned(r2)


async def test_priorities_then_first_come_first_served(bus: Bus, manager: TaskManager) -> None:
    robot = RobotStub(bus, "R1", "hall")
    low = manager.request("go_to_poi", {"poi": "loom"}, priority=1)
    robot.state()
    first = await robot.wait_for("task_assigned")
    assert first.payload["task_id"] == low.id
    robot.start(low.id)
    later = [
        manager.request("go_to_poi", {"poi": "sword"}, priority=1),
        manager.request("go_to_poi", {"poi": "globes"}, priority=9),
        manager.request("go_to_poi", {"poi": "mosaics"}, priority=5),
        manager.request("go_to_poi", {"poi": "telescope"}, priority=9),
    ]
    assert [manager.queue_position(t) for t in later] == [4, 1, 3, 2]
    served = []
    for i in range(4):
        task_id = robot.of_type("task_assigned")[-1].payload["task_id"]
        robot.end(task_id)
        msg = await robot.wait_for("task_assigned", i + 2)
        served.append(msg.payload["task_id"])
        robot.start(msg.payload["task_id"])
    assert served == [later[1].id, later[3].id, later[2].id, later[0].id]


async def test_queue_position_and_wait_are_known_at_once(bus: Bus, manager: TaskManager) -> None:
    robot = RobotStub(bus, "R1", "hall")
    robot.state()
    busy = manager.request("tour", {"tour": "ground"})
    robot.start(busy.id)
    waiting = manager.request("tour", {"tour": "upstairs"}, requester="visitor")
    status = manager.status(waiting)
    assert status["queue_position"] == 1
    assert status["eta_s"] is not None and status["eta_s"] > 0
    third = manager.request("tour", {"tour": "highlights"})
    assert manager.eta_s(third) > manager.eta_s(waiting)


async def test_battery_low_finishes_the_task_then_charges(bus: Bus, manager: TaskManager) -> None:
    r1, r2, r3 = fleet(bus)
    task = manager.request("tour", {"tour": "ground"})
    await r3.wait_for("task_assigned")
    r3.start(task.id)
    r3.endpoint.publish("battery_low", {"robot": "R3", "level": 0.25})
    assert not r3.of_type("task_cancel") and task.state is TaskState.RUNNING
    other = manager.request("go_to_poi", {"poi": "welcome"})
    assert other.robot in ("R1", "R2")  # R3 is not given new work
    taker = r1 if other.robot == "R1" else r2
    taker.node = "hall"  # it leaves its station: a station is free for R3
    taker.state("busy", task_id=other.id)
    r3.end(task.id)
    charge = await r3.wait_for("task_assigned", 2)
    assert charge.payload["net"] == "battery_charge"
    assert charge.payload["params"]["station"] in ("station_a", "station_b")
    assert charge.payload["params"]["node"] in ("charge_a", "charge_b")


async def test_battery_panic_cancels_and_requeues_for_another_robot(
    bus: Bus, manager: TaskManager
) -> None:
    r1, _r2, r3 = fleet(bus)
    task = manager.request("tour", {"tour": "ground"})
    await r3.wait_for("task_assigned")
    r3.start(task.id)
    r1.node = "hall"  # R1 has left its station: R3 can charge there
    r1.state()
    r3.endpoint.publish("battery_panic", {"robot": "R3", "level": 0.05})
    cancel = await r3.wait_for("task_cancel")
    assert cancel.payload["task_id"] == task.id
    assert task.state is TaskState.ASSIGNED and task.robot == "R1"  # the nearest other one
    assert assigned(r1, "give_tour")[0].payload["task_id"] == task.id
    charge = await r3.wait_for("task_assigned", 2)
    assert charge.payload["net"] == "battery_charge"


async def test_lost_robot_task_goes_to_another_after_grace(
    bus: Bus, manager: TaskManager, clock: Clock, events: list[Message]
) -> None:
    r1, r2, r3 = fleet(bus)
    task = manager.request("tour", {"tour": "ground"})
    await r3.wait_for("task_assigned")
    r3.start(task.id)
    clock.now += 6  # R3 falls silent; the others keep reporting
    r1.state()
    r2.state()
    manager.check_timeouts()
    assert not manager.robots["R3"].online and task.robot == "R3"  # grace: may still run
    clock.now += 21
    r1.state()
    r2.state()
    manager.check_timeouts()
    assert task.robot in ("R1", "R2")
    assert states_of(events, task.id)[2:4] == ["running", "queued"]
    r3.state("busy")  # back, still running the old task: told to drop it
    cancel = await r3.wait_for("task_cancel")
    assert cancel.payload["task_id"] == task.id


async def test_staff_reassign_a_task_off_a_broken_robot(bus: Bus, manager: TaskManager) -> None:
    _r1, r2, r3 = fleet(bus)
    task = manager.request("tour", {"tour": "ground"})
    await r3.wait_for("task_assigned")
    r3.start(task.id)
    r3.state("fault")  # broke down: its task is re-queued at once
    assert task.robot in ("R1", "R2")
    manager.reassign(task.id, "R2")
    assert task.robot == "R2"
    assert (await r2.wait_for("task_assigned")).payload["task_id"] == task.id
    with pytest.raises(TaskError):
        manager.reassign(task.id, "R9")


async def test_cancel_reprioritise_and_visitor_at_robot_screen(
    bus: Bus, manager: TaskManager
) -> None:
    robot = RobotStub(bus, "R1", "hall")
    robot.state()
    running = manager.request("tour", {"tour": "ground"})
    robot.start(running.id)
    a = manager.request("go_to_poi", {"poi": "loom"}, priority=1)
    b = manager.request("go_to_poi", {"poi": "sword"}, priority=1)
    manager.reprioritise(b.id, 7)
    assert manager.queue_position(b) == 1
    manager.cancel(a.id, by="operator")
    assert a.state is TaskState.CANCELLED and manager.queue_position(a) is None
    manager.cancel(running.id, by="operator")
    await robot.wait_for("task_cancel")
    assert running.id in [m.payload["task_id"] for m in robot.of_type("task_cancel")]
    assert b.robot == "R1"
    with pytest.raises(TaskError):
        manager.cancel(a.id)
    reply = await robot.endpoint.request(
        "task_request", {"kind": "go_to_poi", "params": {"poi": "globes"}}
    )
    assert reply.type == "task_event"
    mine = manager.get(reply.payload["task_id"])
    assert mine.pinned_robot == "R1" and mine.requester == "R1"
    bad = await robot.endpoint.request("task_request", {"kind": "tour", "params": {"tour": "x"}})
    assert bad.type == "error" and "unknown tour" in bad.payload["reason"]


async def test_idle_robots_go_to_stations_or_the_wait_point(bus: Bus, manager: TaskManager) -> None:
    robots = [RobotStub(bus, name, "gc3") for name in ("R1", "R2", "R3")]
    for robot in robots:
        robot.state()
    nets = sorted(assigned(r)[0].payload["net"] for r in robots)
    assert nets == ["battery_charge", "battery_charge", "navigate_to_point"]
    stations = {
        assigned(r)[0].payload["params"]["station"]
        for r in robots
        if assigned(r)[0].payload["net"] == "battery_charge"
    }
    assert stations == {"station_a", "station_b"}
    waiter = next(r for r in robots if assigned(r)[0].payload["net"] == "navigate_to_point")
    assert assigned(waiter)[0].payload["params"] == {"node": "entrance"}
    # A visitor's task preempts the trip home.
    task = manager.request("go_to_poi", {"poi": "telescope"})
    assert task.robot is not None and task.state is TaskState.ASSIGNED


async def test_a_robot_that_reached_the_wait_point_is_not_sent_there_again(
    bus: Bus, manager: TaskManager
) -> None:
    """task_ended of a trip home comes before the robot's next robot_state: the Task Manager
    must not take the stale node for the truth and send the robot home again and again."""
    robots = [RobotStub(bus, name, "gc3") for name in ("R1", "R2", "R3")]
    for robot in robots:
        robot.state()
    waiter = next(r for r in robots if assigned(r)[0].payload["net"] == "navigate_to_point")
    trip = assigned(waiter)[0].payload["task_id"]
    waiter.start(trip)
    waiter.end(trip)
    await asyncio.sleep(0.05)
    assert len(assigned(waiter)) == 1, [m.payload for m in assigned(waiter)]


async def test_restart_keeps_queued_and_reconciles_running(bus: Bus, manager: TaskManager) -> None:
    queued = Task("q1", "tour", {"tour": "ground"}, 5, "panel", 1)
    still = Task("r1", "tour", {"tour": "upstairs"}, 5, "panel", 2, TaskState.RUNNING, "R1")
    lost = Task("r2", "tour", {"tour": "highlights"}, 5, "panel", 3, TaskState.RUNNING, "R2")
    manager.restore([queued, still, lost])
    assert manager.queue_position(queued) == 1
    r1, r2 = RobotStub(bus, "R1", "gc1"), RobotStub(bus, "R2", "ga1")
    r1.task_id = "r1"
    r1.state("busy")
    assert still.state is TaskState.RUNNING and still.robot == "R1"
    r2.state("idle")  # restarted without it
    assert lost.state in (TaskState.QUEUED, TaskState.ASSIGNED)
    assert manager.robots["R2"].current in ("q1", "r2")
    r1.end("r1")
    assert still.state is TaskState.DONE
    next_id = manager.request("go_to_poi", {"poi": "globes"}).seq
    assert next_id > 3


async def test_a_restored_task_ended_while_no_leader_decided_is_not_run_again(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    """Several processes: the robot ended its task while the leaders changed; its task_ended
    comes again on the link's back-off, after a robot_state that no longer names the task: the
    task ends done, it does not go back to the queue and to the robot again."""
    manager.report_grace_s = 15.0
    ended = Task("t1", "tour", {"tour": "ground"}, 5, "panel", 1, TaskState.RUNNING, "R1")
    lost = Task("t2", "tour", {"tour": "upstairs"}, 5, "panel", 2, TaskState.RUNNING, "R2")
    manager.restore([ended, lost])
    r1, r2 = RobotStub(bus, "R1", "gb2"), RobotStub(bus, "R2", "gc1")
    r1.state("idle")
    r2.state("idle")
    clock.now += 10.0
    r1.state("idle")
    r2.state("idle")
    assert ended.state is TaskState.RUNNING and manager.robots["R1"].current == "t1"
    assert lost.state is TaskState.RUNNING  # within the grace
    r1.end("t1")
    assert ended.state is TaskState.DONE
    assert [m.payload["task_id"] for m in assigned(r1)].count("t1") == 0
    clock.now += 5.0
    r2.state("idle")  # no task_ended came: it no longer runs it
    assert lost.state in (TaskState.QUEUED, TaskState.ASSIGNED)


async def test_bad_requests_are_refused_and_nothing_is_lost(manager: TaskManager) -> None:
    kept = manager.request("tour", {"tour": "ground"})
    for kind, params in [
        ("tour", {"tour": "nope"}),
        ("go_to_poi", {}),
        ("go_to", {"node": 5}),
        ("charge", {"station": "x"}),
        ("fly", {}),
    ]:
        with pytest.raises(TaskError):
            manager.request(kind, params)
    assert [t.id for t in manager.queue.ordered()] == [kept.id]


async def test_restored_task_of_a_robot_no_longer_in_the_site_is_queued(
    manager: TaskManager, events: list[Message]
) -> None:
    orphan = Task("o1", "tour", {"tour": "ground"}, 5, "panel", 4, TaskState.RUNNING, "R7")
    manager.restore([orphan])
    assert orphan.state is TaskState.QUEUED and orphan.robot is None
    assert states_of(events, "o1") == ["queued"]


async def test_button_press_requests_a_task_and_lights_its_led(
    bus: Bus, manager: TaskManager
) -> None:
    from backend.tasks.buttons import ButtonWatcher

    site = manager.site
    watcher = ButtonWatcher(bus.endpoint("buttons"), manager, site)
    await watcher.start()
    outputs: list[Message] = []
    bus.endpoint("building").subscribe("set_output", outputs.append)
    press = {"module": "otb_ground", "point": "button_entrance", "name": "b", "value": 1}
    building = bus.get_endpoint("building")
    assert building is not None
    building.publish("building_input_changed", press)
    building.publish("building_input_changed", press)  # pressed twice: one request
    queued = list(manager.queue.ordered())
    assert len(queued) == 1
    task = queued[0]
    assert task.kind == "tour" and task.params == {"tour": "ground"}
    assert task.requester == "button:button_entrance"
    assert outputs[-1].payload == {"module": "otb_ground", "point": "led_entrance", "value": 1}
    robot = RobotStub(bus, "R1", "hall")
    robot.state()
    assert task.robot == "R1"
    assert outputs[-1].payload["value"] == 1  # a robot is coming: LED still lit
    building.publish("building_input_changed", {**press, "value": 0})  # release: nothing
    robot.start(task.id)
    lit = len(outputs)
    building.publish("building_input_changed", press)  # pressed while running: no duplicate
    assert len(list(manager.queue.ordered())) == 0
    assert len(manager.tasks) == 1 and watcher.presses_ignored == 2
    assert len(outputs) == lit + 1 and outputs[-1].payload["value"] == 1  # acknowledged
    robot.end(task.id)
    assert outputs[-1].payload["value"] == 0  # the tour is over: LED off
    building.publish("building_input_changed", press)  # a new press: a new request
    assert len([t for t in manager.tasks.values() if not t.internal]) == 2
    await watcher.stop()


async def test_site_change_cancels_queued_tasks_it_invalidates(manager: TaskManager) -> None:
    doomed = manager.request("tour", {"tour": "highlights"})
    kept = manager.request("tour", {"tour": "ground"})
    doc = manager.site.model_dump(mode="json")
    doc["tours"] = [t for t in doc["tours"] if t["id"] != "highlights"]
    manager.load_site(validate_site(doc))
    assert doomed.state is TaskState.CANCELLED and "unknown tour" in doomed.reason
    assert kept.state is TaskState.QUEUED and manager.queue_position(kept) == 1


async def test_an_assignment_after_a_site_change_carries_the_new_texts(
    bus: Bus, manager: TaskManager
) -> None:
    robot = RobotStub(bus, "R1", "hall")
    robot.state()
    first = manager.request("tour", {"tour": "ground"})
    robot.start(first.id)
    robot.end(first.id)
    old = assigned(robot, "give_tour")[-1].payload["params"]["points"][0]["text"]
    doc = manager.site.model_dump(mode="json")
    next(p for p in doc["pois"] if p["id"] == "welcome")["text"] = "Welcome, said anew."
    manager.load_site(validate_site(doc))
    second = manager.request("tour", {"tour": "ground"})
    order = assigned(robot, "give_tour")[-1]
    assert order.payload["task_id"] == second.id
    assert order.payload["params"]["points"][0]["text"] == "Welcome, said anew."
    assert old != "Welcome, said anew."


async def test_concurrent_site_edits_both_land() -> None:
    service = SiteService(demo_site(), 1)

    def add(poi_id: str) -> Callable[[dict[str, Any]], Awaitable[None]]:
        async def change(doc: dict[str, Any]) -> None:
            await asyncio.sleep(0)  # let the other edit run in between
            doc["pois"].append({"id": poi_id, "node": "hall"})

        return change

    await asyncio.gather(service.edit(add("a")), service.edit(add("b")))
    ids = {p.id for p in service.site.pois}
    assert {"a", "b"} <= ids and service.version == 3


async def test_a_robot_reporting_no_floor_is_on_its_nodes_floor() -> None:
    bus = Bus()
    site = demo_site()
    tasks = TaskManager(bus.endpoint("task_manager"), site)
    await tasks.start()
    try:
        r1 = RobotStub(bus, "R1", "gc1")
        r1.state()  # an agent without the site on board: node known, floor not
        assert tasks.robots["R1"].as_dict()["floor"] == "F1"
    finally:
        await tasks.stop()


async def test_out_of_service_robot_gets_no_tasks_but_manual_moves(
    bus: Bus, manager: TaskManager
) -> None:
    """Staff take R1 out of service: its tour goes to R2, it is not sent home, new tours skip
    it even when pinned to it, but a go_to pinned to it still reaches it; back in service it
    works again."""
    r1, r2 = RobotStub(bus, "R1", "hall"), RobotStub(bus, "R2", "charge_b")
    tour = manager.request("tour", {"tour": "ground"})
    r1.state()
    r2.state()
    first = await r1.wait_for("task_assigned")  # R1 is nearest to the hall
    assert first.payload["task_id"] == tour.id
    r1.start(tour.id)
    manager.set_out_of_service("R1", True, by="desk")
    assert (await r2.wait_for("task_assigned")).payload["task_id"] == tour.id
    assert manager.robots["R1"].as_dict()["out_of_service"] is True
    pinned_tour = manager.request("tour", {"tour": "highlights"}, robot="R1")
    moved = manager.request("go_to", {"node": "entrance"}, robot="R1")
    order = await r1.wait_for("task_assigned", 2)
    assert order.payload["task_id"] == moved.id
    assert pinned_tour.state is TaskState.QUEUED
    r1.start(moved.id)
    r1.end(moved.id)
    await asyncio.sleep(0)
    assert len(r1.of_type("task_assigned")) == 2  # nothing else, not even "go home"
    manager.set_out_of_service("R1", False, by="desk")
    back = await r1.wait_for("task_assigned", 3)
    assert back.payload["task_id"] == pinned_tour.id
    with pytest.raises(TaskError):
        manager.set_out_of_service("R9", True)


async def test_a_robot_whose_agent_restarted_gives_its_running_task_back(
    bus: Bus, manager: TaskManager, events: list[Message]
) -> None:
    """Killed and restarted within the loss grace, the robot reports no task: the task is
    requeued at once, not left `running` for ever (found by the soak)."""
    _r1, _r2, r3 = fleet(bus)
    task = manager.request("tour", {"tour": "ground"})
    await r3.wait_for("task_assigned")
    r3.start(task.id)
    r3.state("busy")
    assert task.state is TaskState.RUNNING
    r3.task_id = None  # a new agent process: it knows of no task
    r3.state("idle")
    assert states_of(events, task.id)[2:4] == ["running", "queued"]
    assert task.state is not TaskState.RUNNING or task.robot != "R3"


async def test_a_task_the_robot_refuses_as_busy_is_requeued_not_failed(
    bus: Bus, manager: TaskManager, events: list[Message]
) -> None:
    """The server thought R3 free while it ran a task the server forgot (a restart before the
    write-behind): the refused task goes back to the queue and to another robot; R3 gets
    nothing until a robot_state shows it free."""
    r3 = RobotStub(bus, "R3", "entrance")  # the only robot online
    r3.state()
    first = manager.request("tour", {"tour": "ground"})
    order = await r3.wait_for("task_assigned")
    assert order.payload["task_id"] == first.id
    r3.end(first.id, outcome="refused", reason="robot busy with task lost-in-restart")
    assert first.state is TaskState.QUEUED and first.robot is None
    assert states_of(events, first.id)[-1] == "queued"
    assert "R3 refused it: robot busy with task lost-in-restart" in first.reason
    assert len(assigned(r3)) == 1  # not sent back to R3 while it is busy
    r3.task_id = "lost-in-restart"
    r3.state("busy")  # still running what the server does not know: told to drop it
    assert len(assigned(r3)) == 1
    r3.task_id = None
    r3.state("idle")  # free now: the task comes back to it
    again = await r3.wait_for("task_assigned", 2)
    assert again.payload["task_id"] == first.id and first.robot == "R3"


async def test_a_failed_task_always_carries_a_reason(bus: Bus, manager: TaskManager) -> None:
    _r1, _r2, r3 = fleet(bus)
    task = manager.request("tour", {"tour": "ground"})
    order = await r3.wait_for("task_assigned")  # nearest to the hall
    assert order.payload["task_id"] == task.id
    r3.start(task.id)
    r3.end(task.id, outcome="failed")  # no reason in the report
    assert task.state is TaskState.FAILED
    assert task.reason == "R3 reported the task failed without saying why"


async def test_a_robots_task_request_is_answered_once_the_task_is_written(
    bus: Bus, tmp_path: Path
) -> None:
    """The store's background writer is not started: only the answer's own flush writes."""
    engine = make_engine(f"sqlite+aiosqlite:///{tmp_path / 'tasks.db'}")
    try:
        await migrate(engine)
        store = DbStore(make_sessionmaker(engine))
        tm = TaskManager(bus.endpoint("task_manager"), demo_site(), store=store)
        await tm.start()
        robot = RobotStub(bus, "R1", "charge_a")
        robot.state()
        reply = await robot.endpoint.request(
            "task_request", {"kind": "go_to_poi", "params": {"poi": "globes"}}, timeout=10
        )
        assert reply.type == "task_event"
        written = await store.task(reply.payload["task_id"])
        assert written is not None and written.requester == "R1"
        await tm.stop()
    finally:
        await engine.dispose()


async def test_a_repeated_task_request_is_answered_with_the_same_task(
    bus: Bus, manager: TaskManager
) -> None:
    """The robot's link sends a task_request again until it is answered (the first answer may
    be lost): one id is one task."""
    robot = RobotStub(bus, "R1", "charge_a")
    robot.state()
    answers: list[Message] = []
    robot.endpoint.subscribe("task_event", answers.append)
    request = Message(
        type="task_request",
        source="R1",
        payload={"kind": "go_to_poi", "params": {"poi": "globes"}},
    )
    robot.endpoint.send(request)
    robot.endpoint.send(request)
    mine = [a for a in answers if a.correlation_id == request.id]
    assert len(mine) == 2 and mine[0].payload["task_id"] == mine[1].payload["task_id"]
    assert [t.requester for t in manager.tasks.values() if not t.internal] == ["R1"]


async def test_an_assignment_the_robot_reported_on_is_not_sent_again(
    bus: Bus, manager: TaskManager
) -> None:
    """task_started (or task_ended) proves the robot has its task_assigned: resending it after
    that, when its ack was lost, only made the robot see a task it had finished (the tasks
    benchmark saw the resend overtake the robot's next assignment). The robot here speaks
    through another endpoint, as a remote robot's messages arrive, so the Courier keeps what
    it sends until it is acknowledged."""
    link = bus.endpoint("link")
    orders: list[Message] = []
    link.subscribe("task_assigned", orders.append, tap=True)
    link.publish("robot_state", {"robot": "R3", "node": "entrance", "battery": 1.0})
    first = manager.request("tour", {"tour": "ground"}, requester="panel-1")
    second = manager.request("tour", {"tour": "ground"}, requester="panel-1")
    assert [m.payload["task_id"] for m in orders] == [first.id]
    assert manager.courier.pending == 1  # no ack from R3
    link.publish("task_started", {"robot": "R3", "task_id": first.id})
    assert manager.courier.pending == 0
    link.publish("task_ended", {"robot": "R3", "task_id": first.id, "outcome": "done"})
    assert [m.payload["task_id"] for m in orders] == [first.id, second.id]
    assert manager.courier.pending == 1
    link.publish("task_ended", {"robot": "R3", "task_id": second.id, "outcome": "done"})
    assert manager.courier.pending == 0  # an end without a start withdraws it too


async def test_a_robot_that_refuses_at_once_gets_no_errand_until_its_state_comes(
    bus: Bus, manager: TaskManager
) -> None:
    """A robot whose refusal arrives inside the assignment (an in-process VDA 5050 vehicle)
    made dispatch give it errand after errand for ever, freezing the server: a refused robot
    waits for its next robot_state, errands included."""
    r1 = RobotStub(bus, "R1", "hall")  # not at its station: idle, it would be sent there

    def refuse(msg: Message) -> None:
        if msg.destination == "R1":
            r1.endpoint.publish(
                "task_ended",
                {
                    "task_id": msg.payload["task_id"],
                    "robot": "R1",
                    "outcome": "refused",
                    "reason": "robot busy with task x",
                },
            )

    r1.endpoint.subscribe("task_assigned", refuse)
    r1.state()
    created = [t for t in manager.tasks.values() if t.robot == "R1" or t.pinned_robot == "R1"]
    assert len(created) <= 1
    assert manager.robots["R1"].refused
    # Its next state clears the refusal: one errand again, not a storm.
    r1.state()
    assert len([t for t in manager.tasks.values() if t.pinned_robot == "R1"]) <= 2
