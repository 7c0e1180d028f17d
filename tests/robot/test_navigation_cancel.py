"""A cancelled goal stops for good, even when its wake-up and the cancellation coincide.

Python 3.11's ``asyncio.wait_for`` returns the result instead of raising CancelledError when the
awaited thing completes in the same loop pass as the cancellation. A goal cancelled just as
odometry arrived then kept driving in the background, and its commands masked the next goal's
first one (the "reaction drift" of issue 20).
"""

from __future__ import annotations

import asyncio

from guidebot.bus import Bus, Endpoint
from guidebot.messages import Message
from robot_agent.clock import Clock
from robot_agent.navigation import Navigator


async def _waiting_for_odometry(nav: Navigator, odometry: Endpoint) -> asyncio.Task[None]:
    odometry.publish("odometry", {"x": 0.0, "y": 0.0, "theta": 0.0})
    task = asyncio.create_task(nav.drive_to(5.0, 0.0))
    for _ in range(100):
        await asyncio.sleep(0)
        if not nav._odom_event.is_set():
            break
    return task


async def test_goal_cancelled_as_odometry_arrives_stops_for_good() -> None:
    bus = Bus()
    nav = Navigator(bus.endpoint("R1"), Clock(time_scale=1.0), "R1", start_node="a")
    await nav.start()
    commands: list[Message] = []
    bus.endpoint("probe").subscribe("set_velocity", commands.append)
    odometry = bus.endpoint("base")
    try:
        for _ in range(20):
            task = await _waiting_for_odometry(nav, odometry)
            # The same loop pass: odometry wakes the goal, the task gets cancelled.
            odometry.publish("odometry", {"x": 0.01, "y": 0.0, "theta": 0.0})
            task.cancel()
            done, _ = await asyncio.wait([task], timeout=5.0)
            assert done, "the cancelled goal is still running"
            assert task.cancelled(), "the goal swallowed its cancellation and went on driving"
        commands.clear()
        odometry.publish("odometry", {"x": 0.02, "y": 0.0, "theta": 0.0})
        await asyncio.sleep(0.05)
        assert commands == []
    finally:
        await nav.stop()


async def test_request_cancelled_as_its_reply_arrives_is_cancelled() -> None:
    bus = Bus()
    asker, answerer = bus.endpoint("asker"), bus.endpoint("answerer")
    answerer.subscribe("question", lambda m: None)
    for _ in range(20):
        task = asyncio.create_task(asker.request("question", {}, destination="answerer"))
        await asyncio.sleep(0)
        (pending,) = asker._pending.values()
        pending.set_result(Message(type="answer", source="answerer"))
        task.cancel()
        done, _ = await asyncio.wait([task], timeout=5.0)
        assert done and task.cancelled()
