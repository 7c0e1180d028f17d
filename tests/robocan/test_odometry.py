"""The base's odometry joins the two wheels' encoder frames of one period, in whatever order
the master handles them (docs/robocan.md, section 8)."""

from __future__ import annotations

import math
from collections.abc import AsyncIterator

import can
import pytest

from guidebot.bus import Bus
from robot_agent.robocan import protocol as p
from robot_agent.robocan.sim import SimModule
from robot_agent.robocan.stack import RoboCanStack

from .conftest import Watch

PERIOD_S = 0.1  # the encoder period the base driver sets (DriverConfig.encoder_period_ms)
STEP_TICKS = 2000  # 0.1 m of wheel travel per period at 20000 ticks/m


class SilentWheel(SimModule):
    """A motor controller's protocol (description, parameters, modes, enable) whose encoder
    frames the test writes itself."""

    def __init__(self, channel: str, module_id: int) -> None:
        super().__init__(channel, module_id)
        self.description = p.Description(
            p.ModuleKind.MOTOR_CONTROLLER,
            f"wheel_{module_id:02x}",
            (1, 0),
            (
                p.Element(p.ElementKind.MOTOR, p.Role.COMPONENT),
                p.Element(p.ElementKind.PID_VELOCITY, p.Role.AGENT, 1, 0b111),
            ),
        )


class Wheels:
    """Two silent motor controllers online under a master, and a node on their bus whose frames
    keep the receive time the test gives them (as a CAN interface stamps what it receives)."""

    def __init__(self, stack: RoboCanStack, watch: Watch, bus: can.BusABC) -> None:
        self.stack = stack
        self.watch = watch
        self.bus = bus
        self.ticks = {0x02: 0, 0x04: 0}

    def period(self, n: int, *wheels: int, turning: bool = True) -> list[can.Message]:
        """The encoder frames of period ``n`` (received at n times 100 ms); turning on the spot,
        the left wheel runs backwards and the right one forwards."""
        frames = []
        for wheel in wheels:
            sign = 1 if wheel == 0x04 else -1
            if turning and n > 0:
                self.ticks[wheel] += sign * STEP_TICKS
            frames.append(
                can.Message(
                    arbitration_id=wheel,
                    data=p.encoder(0, self.ticks[wheel], sign * 0.1 if turning else 0.0),
                    is_extended_id=False,
                    timestamp=1_000_000.0 + n * PERIOD_S,
                )
            )
        return frames

    def send(self, frames: list[can.Message]) -> None:
        for frame in frames:
            self.bus.send(frame)

    async def deliver(self, frames: list[can.Message]) -> None:
        """Put frames on the bus and wait for the odometry they bring."""
        seen = len(self.watch.of("odometry"))
        self.send(frames)
        await self.watch.wait("odometry", lambda m: len(self.watch.of("odometry")) > seen)

    async def stand_still(self, first: int) -> dict[str, float]:
        """Three periods standing still, one by one; the odometry once the turn is over."""
        for n in range(first, first + 3):
            await self.deliver(self.period(n, 0x02, 0x04, turning=False))
        heading = 5 * 2 * STEP_TICKS / 20000 / self.stack.config.wheel_base_m  # 2.5 rad
        stopped = await self.watch.wait(
            "odometry",
            lambda m: m.payload["w"] == 0.0 and abs(m.payload["theta"] - heading) < 1e-9,
        )
        return stopped.payload


@pytest.fixture
async def wheels(onboard: Bus, channel: str, watch: Watch) -> AsyncIterator[Wheels]:
    left, right = SilentWheel(channel, 0x02), SilentWheel(channel, 0x04)
    bus = can.Bus(interface="virtual", channel=channel.partition(":")[2], preserve_timestamps=True)
    try:
        async with RoboCanStack(onboard.endpoint("robocan"), [channel], simulate=False) as stack:
            await left.start()
            await right.start()
            try:
                await stack.wait_online({0x02, 0x04})
                yield Wheels(stack, watch, bus)
            finally:
                await left.stop()
                await right.stop()
    finally:
        bus.shutdown()


def assert_turned_on_the_spot(stopped: dict[str, float], watch: Watch) -> None:
    assert math.hypot(stopped["x"], stopped["y"]) < 1e-9
    odometry = [m.payload for m in watch.of("odometry")]
    assert all(m["v"] == 0.0 for m in odometry), odometry  # each a period of both wheels


async def test_wheel_frames_handled_out_of_their_periods_order_are_paired_by_their_time(
    wheels: Wheels, watch: Watch
) -> None:
    """A master back from a stall finds five periods of frames waiting and drains the left
    controller's queue before the right one's (section 7: one queue per ID). Pairing "the
    next frame of each wheel" joined the left wheel's five periods with the right wheel's
    first one, and from then on each left frame with the right's previous one: turning on
    the spot, the odometry left the spot, and a loaded robot circled its goal ("stuck")."""
    stalled = [wheels.period(n, 0x02, 0x04) for n in range(6)]
    await wheels.deliver(
        [frame for pair in stalled for frame in pair if frame.arbitration_id == 0x02]
        + [frame for pair in stalled for frame in pair if frame.arbitration_id == 0x04]
    )
    assert_turned_on_the_spot(await wheels.stand_still(6), watch)


async def test_a_wheel_that_starts_reporting_after_the_other_is_paired_from_its_first_period(
    wheels: Wheels, watch: Watch
) -> None:
    """The right wheel reports a period before the left one's first frame (a bring-up that
    ends with 0x04 first, as on a loaded machine): the left wheel's first frame was paired
    with the right's older one, and every later one with the right's previous one."""
    wheels.send(wheels.period(0, 0x04, turning=False))
    await wheels.deliver(wheels.period(1, 0x02, 0x04, turning=False))
    for n in range(2, 7):
        await wheels.deliver(wheels.period(n, 0x02, 0x04))
    assert_turned_on_the_spot(await wheels.stand_still(7), watch)
