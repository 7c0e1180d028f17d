"""The master with the simulated BellBot on a virtual bus: velocity and odometry, hot plug in
several orders, master restart, a critical module lost mid-motion, entities."""

from __future__ import annotations

import asyncio
import logging
import math

import can
import pytest

from guidebot.bus import Bus
from guidebot.testing import wait_until
from robot_agent.robocan import protocol as p
from robot_agent.robocan.busopen import open_bus
from robot_agent.robocan.entities import BaseDriver
from robot_agent.robocan.sim import HeadIo, MotorController, SonarRing
from robot_agent.robocan.stack import RoboCanStack

from .conftest import Watch

BELLBOT_IDS = {0x02, 0x04, 0x08, 0x10, 0x20, 0x40}


async def test_bellbot_comes_online_with_its_drivers(stack: RoboCanStack, watch: Watch) -> None:
    table = {row["module_id"]: row for row in stack.module_table()}
    assert set(table) == BELLBOT_IDS
    assert all(row["state"] == "online" for row in table.values())
    assert table[0x02]["critical"] and not table[0x40]["critical"]
    assert table[0x10]["elements"] == ["sonar", "firing_sequence", "bumper"]
    online = {m.payload["module_id"] for m in watch.of("module_status")}
    assert online == BELLBOT_IDS
    # the firing sequence travelled as a block transfer to both rings
    assert stack.simulator is not None
    ring = stack.simulator.modules[0x10]
    assert isinstance(ring, SonarRing) and ring.firing_sequence == bytes([0, 4, 1, 5, 2, 6, 3, 7])


async def test_velocity_reaches_the_motors_and_odometry_comes_back(
    onboard: Bus, channel: str, watch: Watch
) -> None:
    tap = open_bus(channel)
    frames: list[can.Message] = []
    notifier = can.Notifier(tap, [frames.append], timeout=0.05)
    try:
        async with RoboCanStack(onboard.endpoint("robocan"), [channel], time_scale=10) as stack:
            await stack.wait_online()
            nav = onboard.endpoint("navigation")
            nav.publish("set_velocity", {"v": 0.4, "w": 0.1})
            assert stack.simulator is not None
            left = stack.simulator.modules[0x02]
            right = stack.simulator.modules[0x04]
            assert isinstance(left, MotorController) and isinstance(right, MotorController)
            await wait_until(lambda: left.target != 0 and right.target != 0)
            assert left.target == pytest.approx(0.4 - 0.1 * 0.2, abs=1e-6)
            assert right.target == pytest.approx(0.4 + 0.1 * 0.2, abs=1e-6)
            # at K=10, 0.4 m/s covers a metre in about a quarter of a wall-clock second
            odometry = await watch.wait("odometry", lambda m: m.payload["x"] > 1.0)
            assert odometry.payload["theta"] > 0.1  # turning left
            assert odometry.payload["v"] == pytest.approx(0.4, abs=0.05)
            nav.publish("set_velocity", {"v": 0.0, "w": 0.0})
            await watch.wait("odometry", lambda m: m.payload["v"] == 0.0)
    finally:
        notifier.stop(1.0)
        tap.shutdown()
    commands = [f for f in frames if f.arbitration_id in (0x03, 0x05) and f.data[0] == 0x90]
    assert commands and all(f.dlc == 7 for f in commands)


@pytest.mark.parametrize(
    ("unplug_order", "plug_order"),
    [
        ([0x40, 0x10, 0x02], [0x02, 0x10, 0x40]),
        ([0x02, 0x04, 0x08, 0x10, 0x20, 0x40], [0x40, 0x20, 0x08, 0x04, 0x10, 0x02]),
    ],
)
async def test_hot_plug_and_unplug_in_any_order(
    stack: RoboCanStack, watch: Watch, unplug_order: list[int], plug_order: list[int]
) -> None:
    for module_id in unplug_order:
        await stack.unplug(module_id)
        await watch.wait("module_status", watch.status(module_id, "lost"))
        assert module_id not in stack.online()
    assert stack.online() == BELLBOT_IDS - set(unplug_order)
    for module_id in plug_order:
        await stack.plug(module_id)
        count = len(watch.of("module_status"))
        await watch.wait(
            "module_status",
            lambda m, mid=module_id, n=count: (
                m.payload["module_id"] == mid
                and m.payload["state"] == "online"
                and watch.messages.index(m) >= 0
                and len(watch.of("module_status")) > n
            ),
        )
    await stack.wait_online(BELLBOT_IDS)
    # a module that came back is configured again: its velocity loop answers commands
    onboard_nav = stack.endpoint
    onboard_nav.publish("set_velocity", {"v": 0.2, "w": 0.0})
    assert stack.simulator is not None
    motor = stack.simulator.modules[0x02]
    assert isinstance(motor, MotorController)
    await wait_until(lambda: motor.target == pytest.approx(0.2))


async def test_plug_from_the_onboard_bus(stack: RoboCanStack, watch: Watch) -> None:
    operator = stack.endpoint
    operator.publish("module_plug", {"module_id": 0x20, "plugged": False})
    await watch.wait("module_status", watch.status(0x20, "lost"))
    operator.publish("module_plug", {"module_id": 0x20, "plugged": True})
    await stack.wait_online({0x20})


async def test_master_restart_with_modules_running(
    onboard: Bus, stack: RoboCanStack, watch: Watch
) -> None:
    old = stack.masters[0]
    await stack.restart_master()
    assert stack.masters[0] is not old and not old.running
    await stack.wait_online(BELLBOT_IDS)
    onboard.endpoint("navigation").publish("set_velocity", {"v": 0.3, "w": 0.0})
    start = len(watch.of("odometry"))
    await watch.wait(
        "odometry", lambda m: m.payload["v"] > 0.2 and len(watch.of("odometry")) > start
    )


async def test_critical_module_lost_mid_motion_stops_the_base(
    onboard: Bus, stack: RoboCanStack, watch: Watch
) -> None:
    nav = onboard.endpoint("navigation")
    nav.publish("set_velocity", {"v": 0.5, "w": 0.0})
    assert stack.simulator is not None
    survivor = stack.simulator.modules[0x04]
    assert isinstance(survivor, MotorController)
    await wait_until(lambda: survivor.velocity > 0.4)
    await stack.unplug(0x02)
    fault = await watch.wait("base_fault")
    assert "0x02" in fault.payload["reason"]
    lost = await watch.wait("module_status", watch.status(0x02, "lost"))
    assert lost.payload["critical"] is True
    await wait_until(lambda: survivor.target == 0.0 and survivor.velocity == 0.0)
    # commands are refused while the fault lasts...
    nav.publish("set_velocity", {"v": 0.5, "w": 0.0})
    base = stack.masters[0].drivers_of(BaseDriver)[0]
    assert isinstance(base, BaseDriver) and base.faulted and survivor.target == 0.0
    # ...and accepted again once the controller is back and configured
    await stack.plug(0x02)
    await stack.wait_online({0x02})
    nav.publish("set_velocity", {"v": 0.5, "w": 0.0})
    await wait_until(lambda: survivor.target == pytest.approx(0.5))


async def test_losing_the_head_is_not_a_base_fault(stack: RoboCanStack, watch: Watch) -> None:
    await stack.unplug(0x40)
    lost = await watch.wait("module_status", watch.status(0x40, "lost"))
    assert lost.payload["critical"] is False
    assert not watch.of("base_fault")


async def test_bumper_hit_stops_the_base(onboard: Bus, stack: RoboCanStack, watch: Watch) -> None:
    onboard.endpoint("navigation").publish("set_velocity", {"v": 0.3, "w": 0.0})
    assert stack.simulator is not None
    motor, ring = stack.simulator.modules[0x02], stack.simulator.modules[0x20]
    assert isinstance(motor, MotorController) and isinstance(ring, SonarRing)
    await wait_until(lambda: motor.target > 0)
    ring.press_bumper(5)
    hit = await watch.wait("bumper_hit")
    assert hit.payload == {"ring": 1, "index": 5}
    await wait_until(lambda: motor.target == 0.0)


async def test_head_servos_sonar_touch_and_leds(
    onboard: Bus, stack: RoboCanStack, watch: Watch
) -> None:
    nets = onboard.endpoint("nets")
    nets.publish("move_servos", {"servos": {"head_pan": 30, "eyelid_left": -10}, "speed": 120})
    done = {
        (await watch.wait("servo_in_position", lambda m, s=s: m.payload["servo"] == s)).payload[
            "position"
        ]
        for s in ("head_pan", "eyelid_left")
    }
    assert done == {30.0, -10.0}
    # a servo told to go where it already is still confirms
    count = len(watch.of("servo_in_position"))
    nets.publish("move_servos", {"servos": {"head_pan": 30}, "speed": 120})
    await watch.wait(
        "servo_in_position",
        lambda m: m.payload["servo"] == "head_pan" and len(watch.of("servo_in_position")) > count,
    )
    ranges = await watch.wait("sonar_ranges", lambda m: m.payload["ring"] == 0)
    assert ranges.payload["ranges"] == [pytest.approx(3.0)] * 8
    assert stack.simulator is not None
    head = stack.simulator.modules[0x40]
    assert isinstance(head, HeadIo)
    head.touch(0)
    assert (await watch.wait("button_pressed")).payload == {"button": "head_top"}
    nets.publish("set_leds", {"leds": {"eye_right": 200, "nonsense": 1}})
    await wait_until(lambda: head.outputs[1] == 200)


async def test_bad_onboard_commands_are_refused_and_lose_nothing(
    onboard: Bus, stack: RoboCanStack, watch: Watch, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="robot_agent.robocan")
    nav = onboard.endpoint("navigation")
    nav.publish("set_velocity", {"v": "fast", "w": 0.0})
    nav.publish("set_velocity", {"v": math.inf, "w": 0.0})
    nav.publish("move_servos", {"servos": {"tail": 10}})
    assert "set_velocity refused" in caplog.text and "unknown servo 'tail'" in caplog.text
    nav.publish("set_velocity", {"v": 0.1, "w": 0.0})
    assert stack.simulator is not None
    motor = stack.simulator.modules[0x02]
    assert isinstance(motor, MotorController)
    await wait_until(lambda: motor.target == pytest.approx(0.1))


async def test_battery_level_charging_and_panic(
    onboard: Bus, stack: RoboCanStack, watch: Watch
) -> None:
    logic = onboard.endpoint("battery_logic")
    first = await watch.wait("battery_level")
    assert first.payload["level"] > 0.9 and first.payload["charging"] is False
    logic.publish("sim_set_battery", {"level": 0.05})
    panic = await watch.wait("battery_panic")
    assert panic.payload == {"robot": "R1", "level": 0.05}
    logic.publish("set_charging", {"on": True})
    charging = await watch.wait("battery_level", lambda m: m.payload["charging"])
    assert charging.payload["level"] >= 0.05


async def test_garbage_is_counted_and_starves_nobody(stack: RoboCanStack, watch: Watch) -> None:
    master = stack.masters[0]
    junk = open_bus(stack.bus_specs[0])
    try:
        before = master.counters
        bad_before, unknown_before = before.bad_frame, before.unknown_id
        overflow_before = before.overflow
        for frame in (
            can.Message(arbitration_id=0x000, data=b"\x01", is_extended_id=False),
            can.Message(arbitration_id=0x7FF, data=b"\x01\x02", is_extended_id=False),
            can.Message(arbitration_id=0x1ABCDE, data=b"\x00", is_extended_id=True),
            can.Message(
                arbitration_id=0x02, data=bytes([p.Op.ENCODER, 0, 1]), is_extended_id=False
            ),
            can.Message(arbitration_id=0x02, data=bytes([0x66, 1, 2]), is_extended_id=False),
            can.Message(
                arbitration_id=0x02, data=bytes([p.Op.BLOCK_DATA, 7, 1, 2]), is_extended_id=False
            ),
        ):
            junk.send(frame)

        # a module that floods the bus with junk from a new ID, from its own thread
        def flood() -> None:
            for i in range(3000):
                junk.send(
                    can.Message(
                        arbitration_id=0x30, data=bytes([0x77, i % 256]), is_extended_id=False
                    )
                )

        await asyncio.to_thread(flood)
        await wait_until(
            lambda: (
                master.counters.bad_frame + master.counters.overflow
                >= bad_before + overflow_before + 3003
            )
        )
        assert master.counters.unknown_id >= unknown_before + 2
        assert master.counters.block_errors >= 1
        # everybody else stayed online and keeps publishing
        start = len(watch.of("odometry"))
        await watch.wait("odometry", lambda m: len(watch.of("odometry")) > start + 3)
        assert stack.online() >= {0x02, 0x04, 0x08, 0x10, 0x20, 0x40}
        assert master.running
    finally:
        junk.shutdown()


async def test_disable_and_enable_a_module(stack: RoboCanStack, watch: Watch) -> None:
    await stack.set_enabled(0x10, False)
    disabled = await watch.wait("module_status", watch.status(0x10, "disabled"))
    assert disabled.payload["name"] == "sonar_ring_10"
    assert stack.simulator is not None
    ring = stack.simulator.modules[0x10]
    await wait_until(lambda: not ring.enabled)
    # it keeps its watchdog going: disabled, not lost, and no sonar frames from it
    mark = len(watch.messages)
    await watch.wait("sonar_ranges", lambda m: m.payload["ring"] == 1)
    await watch.wait(
        "sonar_ranges", lambda m: m.payload["ring"] == 1 and watch.messages.index(m) > mark
    )
    assert not [
        m for m in watch.messages[mark:] if m.type == "sonar_ranges" and m.payload["ring"] == 0
    ]
    assert not [m for m in watch.messages[mark:] if m.type == "module_status"]
    with pytest.raises(RuntimeError, match="expected one of"):
        await stack.set_enabled(0x10, False)
    await stack.set_enabled(0x10, True)
    await watch.wait("module_status", watch.status(0x10, "online"))
    await watch.wait(
        "sonar_ranges", lambda m: m.payload["ring"] == 0 and watch.messages.index(m) > mark
    )


async def test_two_buses_two_masters(onboard: Bus, channel: str, watch: Watch) -> None:
    second = channel + "-b"
    async with RoboCanStack(
        onboard.endpoint("robocan"), [channel, second], layout={0x02: "motor"}
    ) as stack:
        await stack.wait_online({0x02})
        assert len(stack.masters) == 2
        raw = open_bus(second)
        try:
            raw.send(
                can.Message(
                    arbitration_id=0x70,
                    data=p.watchdog(p.SlaveState.DISABLED),
                    is_extended_id=False,
                )
            )
            await wait_until(lambda: 0x70 in stack.masters[1].modules)
        finally:
            raw.shutdown()
        assert 0x70 not in stack.masters[0].modules
        assert 0x02 not in stack.masters[1].modules


async def test_unopenable_bus_is_a_clear_error(onboard: Bus) -> None:
    from robot_agent.robocan.busopen import BusOpenError, BusSpecError

    with pytest.raises(BusSpecError, match="expected 'interface:channel'"):
        RoboCanStack(onboard.endpoint("a"), ["can0"], simulate=False)
    with pytest.raises(ValueError, match="virtual bus"):
        RoboCanStack(onboard.endpoint("b"), ["socketcan:can0"], simulate=True)
    with pytest.raises(BusSpecError, match="unknown interface"):
        async with RoboCanStack(onboard.endpoint("c"), ["warp:0"], simulate=False):
            pass
    with pytest.raises(BusOpenError, match="socketcan:nope0"):
        async with RoboCanStack(onboard.endpoint("d"), ["socketcan:nope0"], simulate=False):
            pass


async def test_battery_alarms_fire_once_per_discharge(
    onboard: Bus, stack: RoboCanStack, watch: Watch
) -> None:
    await watch.wait("battery_level")
    for level in (0.24, 0.22, 0.26, 0.2):  # hovering around "low" (0.25): one alarm
        stack.set_battery_level(level)
        await watch.wait("battery_level", lambda m, lv=level: m.payload["level"] == lv)
    assert len(watch.of("battery_low")) == 1
    stack.set_battery_level(0.9)  # charged: re-armed
    await watch.wait("battery_level", lambda m: m.payload["level"] == 0.9)
    stack.set_battery_level(0.2)
    await watch.wait(
        "battery_level", lambda m: m.payload["level"] == 0.2 and len(watch.of("battery_low")) == 2
    )
    assert not watch.of("battery_panic")


async def test_a_stalled_process_does_not_lose_its_modules(
    stack: RoboCanStack, watch: Watch
) -> None:
    """A loaded machine can stop the event loop for longer than the 350 ms time-out; the time
    the master itself was not running must not count against the modules."""
    import time

    master = stack.masters[0]
    time.sleep(0.8)  # noqa: ASYNC251 -- the stall under test: blocks the whole loop
    start = len(watch.of("odometry"))
    await watch.wait("odometry", lambda m: len(watch.of("odometry")) > start + 3)
    assert master.counters.stalls >= 1
    assert not [m for m in watch.of("module_status") if m.payload["state"] == "lost"]
    assert stack.online() == BELLBOT_IDS


async def test_shutdown_reports_no_loss(onboard: Bus, channel: str, watch: Watch) -> None:
    async with RoboCanStack(onboard.endpoint("robocan"), [channel]) as stack:
        await stack.wait_online()
    assert not [m for m in watch.of("module_status") if m.payload["state"] == "lost"]
    assert not watch.of("base_fault")
