"""Rules docs/robocan.md now states where a hardware maker had to guess (issue 19): sonar 255,
the firing order of a ring with more sonars than configured, refused CONFIG blocks, bumper state
on ENABLE, the broadcast ID, battery voltage units, a motor controller's own bumper stop."""

from __future__ import annotations

import pytest

from guidebot.bus import Bus
from guidebot.testing import wait_until
from robot_agent.robocan import protocol as p
from robot_agent.robocan.master import CommandFailed
from robot_agent.robocan.sim import MotorController, SonarRing
from robot_agent.robocan.stack import RoboCanStack

from .conftest import Watch, sim_module
from .rawslave import Tap


def test_sonar_255_is_nothing_in_range_not_5_metres() -> None:
    frame = p.sonar(0, 0, [0.5, None, 7.0, 5.08, 0.0])
    assert list(frame[3:]) == [25, 255, 255, 254, 0]
    _, _, ranges = p.parse_sonar(frame)
    assert ranges == [pytest.approx(0.5), None, None, pytest.approx(5.08), 0.0]


async def test_nothing_in_range_reaches_navigation_as_none(
    stack: RoboCanStack, watch: Watch
) -> None:
    ring = sim_module(stack, 0x10, SonarRing)
    ring.ranges[3] = None
    ring.ranges[4] = 9.0  # beyond the sonar's reach
    message = await watch.wait(
        "sonar_ranges", lambda m: m.payload["ring"] == 0 and m.payload["ranges"][3] is None
    )
    assert message.payload["ranges"][4] is None
    assert message.payload["ranges"][0] == pytest.approx(3.0)


async def test_a_ring_with_more_sonars_than_configured_fires_them_all(
    onboard: Bus, channel: str, watch: Watch
) -> None:
    ring = SonarRing(channel, 0x30, sonars=12)
    async with RoboCanStack(onboard.endpoint("robocan"), [channel], simulate=False) as stack:
        await ring.start()
        try:
            await stack.wait_online({0x30})
            # the configured order (0 4 1 5 2 6 3 7), then the sonars it does not list
            assert ring.firing_sequence == bytes([0, 4, 1, 5, 2, 6, 3, 7, 8, 9, 10, 11])
            message = await watch.wait("sonar_ranges")
            assert message.payload["ranges"] == [pytest.approx(3.0)] * 12
        finally:
            await ring.stop()


async def test_a_config_block_with_bad_content_is_refused_once(
    stack: RoboCanStack, tap: Tap
) -> None:
    master = stack.masters[0]
    start = len(tap.frames)
    # sonar 9 does not exist on an eight-sonar ring
    with pytest.raises(CommandFailed, match="REFUSED"):
        await master.send_block(0x10, p.BlockType.CONFIG, bytes([1, 0, 0, 9]))
    # The tap reads the bus in its own thread: it may see the answer after the master did.
    refusal = await tap.expect(0x10, p.Op.BLOCK_END, start)
    assert refusal == bytes([p.Op.BLOCK_END, p.EndStatus.REFUSED, p.BlockType.CONFIG])
    assert len(tap.of(0x10, p.Op.BLOCK_END, start)) == 1
    assert len(tap.of(0x11, p.Op.BLOCK_START, start)) == 1  # not sent again
    ring = sim_module(stack, 0x10, SonarRing)
    assert ring.firing_sequence == bytes([0, 4, 1, 5, 2, 6, 3, 7])


async def test_a_bumper_pressed_while_disabled_is_reported_on_enable(
    stack: RoboCanStack, watch: Watch
) -> None:
    ring = sim_module(stack, 0x20, SonarRing)
    await stack.set_enabled(0x20, False)
    ring.press_bumper(3)  # not sent: the module is disabled
    assert not watch.of("bumper_hit")
    await stack.set_enabled(0x20, True)
    hit = await watch.wait("bumper_hit")
    assert hit.payload == {"ring": 1, "index": 3}


async def test_only_master_start_and_stop_act_on_the_broadcast_id(
    stack: RoboCanStack, tap: Tap
) -> None:
    start = len(tap.frames)
    tap.send(p.BROADCAST_ID, bytes([p.Op.QUERY]))
    tap.send(0x41, bytes([p.Op.QUERY]))  # addressed: handled after the broadcast one
    await tap.expect(0x40, p.Op.BLOCK_START, start)
    answered = {m.arbitration_id for m in tap.frames[start:] if m.data[0] == p.Op.BLOCK_START}
    assert answered == {0x40}


async def test_battery_voltage_is_volts_on_board(stack: RoboCanStack, watch: Watch) -> None:
    level = await watch.wait("battery_level")
    assert 20.0 < level.payload["voltage"] < 30.0  # 22..26 V, sent in millivolts


async def test_a_motor_controller_stops_on_its_own_bumper(
    onboard: Bus, stack: RoboCanStack, watch: Watch
) -> None:
    """Without the master (a dead master cannot act on bumper_hit), the controller carrying
    the bumper stops its motor itself."""
    motor = sim_module(stack, 0x04, MotorController)
    onboard.endpoint("navigation").publish("set_velocity", {"v": 0.3, "w": 0.0})
    await wait_until(lambda: motor.target > 0)
    await stack.masters[0].stop()  # the master dies: nobody relays the contact
    motor.press_bumper(0)
    assert motor.target == 0.0
