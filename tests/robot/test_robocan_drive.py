"""A robot on RoboCAN hardware reaches its goals however its wheels' frames reach the master.

Real pieces: the RoboCAN master and its base driver, the navigator's closed loop, and the
simulated motor controllers on a python-can virtual bus. Here the controllers run in a thread
with an event loop of their own, as hardware does: when the agent's process stands still they
go on sending, and the master finds several periods of encoder frames waiting when it wakes.
"""

from __future__ import annotations

import asyncio
import itertools
import math
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

from guidebot.bus import Bus
from guidebot.messages import Message
from robot_agent.clock import Clock
from robot_agent.navigation import Navigator
from robot_agent.robocan.sim import Simulator
from robot_agent.robocan.sim.motor import MotorController
from robot_agent.robocan.stack import RoboCanStack

TIME_SCALE = 20.0  # as the end-to-end tests (tests/robot/test_e2e.py)
_channels = itertools.count()


@contextmanager
def motors_elsewhere(channel: str) -> Iterator[Simulator]:
    """The two simulated motor controllers, powered on, in a thread with its own event loop."""
    simulator = Simulator(channel, time_scale=TIME_SCALE, layout={0x02: "motor", 0x04: "motor"})
    loop = asyncio.new_event_loop()
    started = threading.Event()

    def run() -> None:
        asyncio.set_event_loop(loop)
        loop.run_until_complete(simulator.start())
        started.set()
        loop.run_forever()
        loop.run_until_complete(simulator.stop())
        loop.close()

    thread = threading.Thread(target=run, name="motor-controllers")
    thread.start()
    try:
        assert started.wait(10.0), "the simulated motor controllers did not start"
        yield simulator
    finally:
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10.0)


def wheels_travel(simulator: Simulator) -> tuple[float, float]:
    """The distance each wheel really ran (the simulated firmware's own account)."""
    left, right = simulator.modules[0x02], simulator.modules[0x04]
    assert isinstance(left, MotorController) and isinstance(right, MotorController)
    return left.distance, right.distance


async def test_a_robot_whose_agent_froze_past_the_watchdog_still_reaches_its_goal() -> None:
    """The agent's process stands still for 0.6 s in mid-drive (longer than the modules'
    350 ms time-out) while the motor controllers go on: the master then drains six periods of
    the left wheel's frames before those of the right one. The base paired "the next frame of
    each wheel", so from then on every odometry report joined one wheel's period with the
    other's previous one: the heading swung by a radian a report at this time scale and the
    robot circled its goal until "stuck"."""
    channel = f"virtual:test-drive-{next(_channels)}-{time.monotonic_ns()}"
    bus = Bus()
    clock = Clock(time_scale=TIME_SCALE)
    nav = Navigator(bus.endpoint("R1"), clock, "R1")
    loop = asyncio.get_running_loop()
    stalls: list[asyncio.Handle] = []

    def freeze_once(message: Message) -> None:
        if message.payload["v"] > 0 and not stalls:
            stalls.append(loop.call_soon(time.sleep, 0.6))  # the whole agent stands still

    with motors_elsewhere(channel) as simulator:
        async with RoboCanStack(bus.endpoint("robocan"), [channel], simulate=False) as stack:
            await stack.wait_online({0x02, 0x04})
            await nav.start()
            try:
                await nav.turn_to(0.0)
                x, y = nav.x + 10.0, nav.y
                bus.endpoint("watch").subscribe("set_velocity", freeze_once, tap=True)
                assert await asyncio.wait_for(nav.drive_to(x, y), 30.0) is True
            finally:
                await nav.stop()
            assert stalls
            [master] = stack.masters
            assert master.counters.stalls >= 1  # the master knew its own absence for one
            assert master.counters.modules_lost == 0
            assert math.hypot(nav.x - x, nav.y - y) < nav.tolerance_m
            # The odometry is the wheels' own account: the heading it gives is theirs.
            left, right = wheels_travel(simulator)
            heading = (right - left) / stack.config.wheel_base_m
            assert abs(math.remainder(nav.theta - heading, math.tau)) < 0.05
