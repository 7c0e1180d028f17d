"""The Task Manager's handlers take payload models (guidebot/bus.py, ``on``) and read them as
the dict readers did: what a message leaves out changes nothing, and a task_request that is
not one is still answered."""

from __future__ import annotations

import asyncio

from backend.tasks import TaskManager
from guidebot.bus import Bus
from guidebot.messages import Message

from .helpers import RobotStub


async def test_a_robot_state_without_a_battery_leaves_the_battery_as_it_was(
    bus: Bus, manager: TaskManager
) -> None:
    r1 = RobotStub(bus, "R1", "charge_a", battery=0.4)
    r1.state()
    assert manager.robots["R1"].battery == 0.4
    r1.endpoint.publish("robot_state", {"robot": "R1", "node": "hall", "mode": "busy"})
    robot = manager.robots["R1"]
    assert (robot.battery, robot.node, robot.mode) == (0.4, "hall", "busy")
    r1.endpoint.publish("robot_state", {"robot": "R1", "battery": 0.3})
    assert (robot.battery, robot.mode) == (0.3, "idle")  # no mode: idle, as always


async def test_a_robot_speaks_only_for_itself(bus: Bus, manager: TaskManager) -> None:
    r1 = RobotStub(bus, "R1", "charge_a", battery=0.9)
    r1.state()
    r1.endpoint.publish("robot_state", {"robot": "R2", "node": "hall", "battery": 0.1})
    r1.endpoint.publish("battery_panic", {"robot": "R2", "level": 0.05})
    r2 = manager.robots["R2"]
    assert not r2.online and r2.battery == 1.0 and not r2.needs_charge


async def test_a_task_request_that_is_not_one_is_refused_with_an_error(
    bus: Bus, manager: TaskManager
) -> None:
    panel = bus.endpoint("panel-1")
    answers: list[Message] = []
    got = asyncio.Event()

    def answer(message: Message) -> None:
        answers.append(message)
        got.set()

    panel.subscribe("error", answer)
    panel.publish("task_request", {"kind": "tuor", "params": {"tour": "ground"}})
    await asyncio.wait_for(got.wait(), 5)
    assert answers[0].payload["code"] == "task_refused"
    assert "'tour', 'go_to_poi'" in answers[0].payload["reason"]  # the kinds it may be
    assert not manager.tasks
