"""Handover (issue 36): a tour taken from its robot mid-way goes on with another robot from the
stop the visitor is at, and every task_event says so. Task Manager over a real bus with scripted
robots; tests/robot/test_handover.py runs the same over real robot processes."""

from __future__ import annotations

from typing import Any

from backend.tasks import Task, TaskManager, TaskState
from guidebot.bus import Bus
from guidebot.messages import Message

from .conftest import Clock
from .helpers import RobotStub

GROUND = ["welcome", "mosaics", "amphorae", "sword", "loom"]


def progress(robot: RobotStub, task_id: str, index: int, stage: str, poi: str) -> None:
    robot.endpoint.publish(
        "tour_progress",
        {
            "task_id": task_id,
            "robot": robot.name,
            "index": index,
            "total": 5,
            "poi": poi,
            "stage": stage,
        },
    )


def last_event(events: list[Message], task_id: str) -> dict[str, Any]:
    return [m.payload for m in events if m.payload["task_id"] == task_id][-1]


async def tour_at_stop_3(bus: Bus, manager: TaskManager) -> tuple[RobotStub, RobotStub, str]:
    """R1 gives the ground tour and has explained its third stop; R2 is idle at home."""
    r1 = RobotStub(bus, "R1", "hall")
    r1.state()
    task = manager.request("tour", {"tour": "ground"}, requester="panel-1")
    await r1.wait_for("task_assigned")
    r1.start(task.id)
    r2 = RobotStub(bus, "R2", "charge_b")
    r2.state()
    for i, poi in enumerate(GROUND[:3], start=1):
        progress(r1, task.id, i, "arrived", poi)
        progress(r1, task.id, i, "explained", poi)
    r1.node = "amphorae_spot"
    return r1, r2, task.id


async def test_a_faulty_robot_hands_the_tour_over_from_the_visitors_stop(
    bus: Bus, manager: TaskManager, events: list[Message]
) -> None:
    r1, r2, task_id = await tour_at_stop_3(bus, manager)
    r1.state("fault", task_id=task_id)
    order = await r2.wait_for("task_assigned")
    # R2 is sent to the visitor's stop, not to the start: the points from stop 3 on, numbered
    # as in the whole tour.
    points = order.payload["params"]["points"]
    assert [p["poi"] for p in points] == GROUND[2:]
    assert [p["index"] for p in points] == [3, 4, 5] and points[0]["total"] == 5
    handover = order.payload["handover"]
    assert handover["from_robot"] == "R1" and handover["robot"] == "R2"
    assert handover["stop"] == 3 and handover["reason"] == "robot fault"
    told = last_event(events, task_id)
    assert told["robot"] == "R2" and told["handover"]["stop"] == 3
    assert told["arrival_s"] is not None and told["arrival_s"] > 0  # when R2 is at the visitor
    assert task_id in {m.payload["task_id"] for m in r1.of_type("task_cancel")}
    r2.start(task_id)
    progress(r2, task_id, 3, "arrived", "amphorae")
    task = manager.get(task_id)
    assert task.handover is not None and task.handover["arrived_after_s"] is not None
    told = last_event(events, task_id)
    assert told["progress"]["index"] == 3 and told["progress"]["total"] == 5
    assert told["handover"]["arrived_after_s"] is not None
    progress(r2, task_id, 3, "explained", "amphorae")
    progress(r2, task_id, 4, "arrived", "sword")
    assert last_event(events, task_id)["progress"]["index"] == 4
    r2.end(task_id)
    assert task.state is TaskState.DONE


async def test_a_robot_out_of_service_battery_panic_or_lost_hands_over_too(
    bus: Bus, manager: TaskManager, clock: Clock
) -> None:
    _r1, r2, task_id = await tour_at_stop_3(bus, manager)
    manager.set_out_of_service("R1", True, by="staff")
    order = await r2.wait_for("task_assigned")
    assert order.payload["params"]["points"][0]["index"] == 3
    # R2 breaks in turn before it reached the visitor: the next robot still goes to stop 3.
    r3 = RobotStub(bus, "R3", "entrance")
    r3.state()
    r2.endpoint.publish("battery_panic", {"robot": "R2", "level": 0.05})
    order = await r3.wait_for("task_assigned")
    assert order.payload["params"]["points"][0]["index"] == 3
    assert order.payload["handover"]["from_robot"] == "R2"
    r3.start(task_id)
    progress(r3, task_id, 3, "arrived", "amphorae")
    progress(r3, task_id, 3, "explained", "amphorae")
    progress(r3, task_id, 4, "arrived", "sword")
    # R3 is lost past the grace period at stop 4: R2, charged again, continues from stop 4.
    r2.battery = 1.0
    clock.now += 6
    r2.state()
    manager.check_timeouts()
    clock.now += 21
    r2.state()
    manager.check_timeouts()
    order = [m for m in r2.of_type("task_assigned") if m.payload["task_id"] == task_id][-1]
    assert [p["index"] for p in order.payload["params"]["points"]] == [4, 5]
    assert order.payload["handover"]["reason"] == "robot lost"


async def test_a_tour_broken_before_its_first_stop_starts_again(
    bus: Bus, manager: TaskManager, events: list[Message]
) -> None:
    r1 = RobotStub(bus, "R1", "hall")
    r1.state()
    task = manager.request("tour", {"tour": "ground"})
    await r1.wait_for("task_assigned")
    r1.start(task.id)
    r2 = RobotStub(bus, "R2", "charge_b")
    r2.state()
    r1.state("fault", task_id=task.id)
    order = await r2.wait_for("task_assigned")
    assert [p["poi"] for p in order.payload["params"]["points"]] == GROUND
    assert order.payload["handover"] is None and last_event(events, task.id)["handover"] is None


async def test_a_tour_its_robot_failed_on_a_base_fault_is_handed_over_not_failed(
    bus: Bus, manager: TaskManager, events: list[Message]
) -> None:
    r1, r2, task_id = await tour_at_stop_3(bus, manager)
    reason = "navigation to ga2 failed: base fault: motor controller 0x02 lost: time-out"
    r1.end(task_id, "failed", reason)
    order = await r2.wait_for("task_assigned")
    assert order.payload["task_id"] == task_id
    assert [p["index"] for p in order.payload["params"]["points"]] == [3, 4, 5]
    assert order.payload["handover"]["reason"] == f"R1 broke down: {reason}"
    assert "failed" not in [m.payload["state"] for m in events if m.payload["task_id"] == task_id]
    # Its robot_state repeats that it ended the task failed: nothing more happens to the task.
    before = len(events)
    ended = [{"task_id": task_id, "outcome": "failed", "reason": reason}]
    r1.state("fault", ended=ended)
    r1.state("idle", ended=ended)
    assert manager.get(task_id).robot == "R2"
    assert not [m for m in events[before:] if m.payload["task_id"] == task_id]
    # Alone, the broken robot never gets it back (it waits for another robot).
    r2.start(task_id)
    # A failure of the visit itself (not of the robot) still fails it.
    r2.end(task_id, "failed", "navigation to gc1 failed: no path")
    assert manager.get(task_id).state is TaskState.FAILED


async def test_after_a_server_restart_the_robots_own_stop_is_where_the_tour_goes_on(
    bus: Bus, manager: TaskManager
) -> None:
    """A restarted server has no tour_progress of a running tour: the robot_state's ``poi``
    (its last shown point) tells the visitor's stop (the soak's battery panics after a server
    kill started tours again from stop 1)."""
    running = Task("t1", "tour", {"tour": "ground"}, 5, "panel", 1, TaskState.RUNNING, "R1")
    manager.restore([running])
    r1 = RobotStub(bus, "R1", "hall")
    r1.task_id = "t1"
    r1.state("busy", poi="amphorae")
    assert running.state is TaskState.RUNNING
    r2 = RobotStub(bus, "R2", "charge_b")
    r2.state()
    r1.endpoint.publish("battery_panic", {"robot": "R1", "level": 0.05})
    order = await r2.wait_for("task_assigned")
    assert [p["poi"] for p in order.payload["params"]["points"]] == GROUND[2:]
    assert order.payload["handover"]["stop"] == 3


async def test_a_robot_broken_on_a_tour_alone_never_gets_it_back(
    bus: Bus, manager: TaskManager, events: list[Message]
) -> None:
    r1 = RobotStub(bus, "R1", "hall")
    r1.state()
    task = manager.request("tour", {"tour": "ground"})
    await r1.wait_for("task_assigned")
    r1.start(task.id)
    reason = "navigation to ga2 failed: base fault: motor controller 0x02 lost: time-out"
    r1.end(task.id, "failed", reason)
    ended = [{"task_id": task.id, "outcome": "failed", "reason": reason}]
    for _ in range(3):
        r1.state("idle", ended=ended)
    assert task.state is TaskState.QUEUED and task.robot is None
    assert [m.payload["state"] for m in events if m.payload["task_id"] == task.id] == [
        "queued",
        "assigned",
        "running",
        "queued",
    ]
