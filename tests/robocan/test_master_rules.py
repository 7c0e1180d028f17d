"""Master rules a module written from the spec alone relies on (issue 19): data right after the
ENABLE acknowledgement, element numbers in data frames, unknown block types, master-direction
opcodes from a slave ID."""

from __future__ import annotations

import math

import pytest

from guidebot.bus import Bus
from guidebot.testing import wait_until
from robot_agent.robocan import protocol as p
from robot_agent.robocan.entities import BaseDriver
from robot_agent.robocan.sim import SimModule
from robot_agent.robocan.stack import RoboCanStack

from .conftest import Watch
from .rawslave import RawSlave, Tap


class CustomModule(SimModule):
    """A simulated module with any element list (the firmware skeleton does the protocol)."""

    def __init__(self, channel: str, module_id: int, *elements: p.Element) -> None:
        super().__init__(channel, module_id)
        self.description = p.Description(
            p.ModuleKind.OTHER, f"custom_{module_id:02x}", (1, 0), elements
        )
        self.velocity_commands: dict[int, float] = {}

    def on_command(self, op: int, data: bytes) -> p.AckStatus | None:
        if op == p.Op.SET_VELOCITY and self.enabled:
            element, velocity, _ = p.parse_set_velocity(data)
            self.velocity_commands[element] = velocity
        return None


# --- data frames right after the ACK to ENABLE ----------------------------------------------


async def test_a_frame_sent_right_after_the_enable_ack_is_delivered(
    onboard: Bus, channel: str, watch: Watch
) -> None:
    """Section 4.5: the module is ONLINE after its ACK; a one-shot frame sent then (a bumper
    already pressed) must not be lost."""
    async with RoboCanStack(onboard.endpoint("robocan"), [channel], simulate=False) as stack:
        slave = RawSlave(channel, 0x62)
        try:
            description = p.Description(
                p.ModuleKind.OTHER,
                "bumper_strip",
                (1, 0),
                (p.Element(p.ElementKind.BUMPER, p.Role.COMPONENT, 4),),
            )
            enable = await slave.bring_up(description)
            assert enable == p.enable(p.MODULE, True)
            slave.send(p.ack(p.Op.ENABLE, p.MODULE))
            slave.send(p.mask_frame(p.Op.BUMPERS, 0, 0b10))  # in the same burst as the ACK
            hit = await watch.wait("bumper_hit", timeout=3)
            assert hit.payload == {"ring": 0x62, "index": 1}
            assert stack.masters[0].counters.not_online == 0
        finally:
            await slave.close()


# --- element numbers --------------------------------------------------------------------------


async def test_a_frame_naming_an_element_of_another_kind_is_bad(
    stack: RoboCanStack, tap: Tap, watch: Watch
) -> None:
    master = stack.masters[0]
    bad, errors = master.counters.bad_frame, master.modules[0x40].errors
    tap.send(0x40, p.mask_frame(p.Op.INPUTS, 0, 0b1))  # element 0 of the head is a servo
    await wait_until(lambda: master.counters.bad_frame > bad, timeout=3)
    assert master.modules[0x40].errors == errors + 1
    assert not watch.of("button_pressed")
    tap.send(0x40, p.mask_frame(p.Op.INPUTS, 1, 0b1))  # element 1 is the touch element
    assert (await watch.wait("button_pressed")).payload == {"button": "head_top"}


async def test_an_encoder_frame_for_a_missing_element_leaves_odometry_alone(
    stack: RoboCanStack, tap: Tap, watch: Watch
) -> None:
    master = stack.masters[0]
    start = len(watch.of("odometry"))
    await watch.wait("odometry", lambda m: len(watch.of("odometry")) > start)
    bad = master.counters.bad_frame
    tap.send(0x02, p.encoder(7, 100_000, 0.0))  # 5 m of ticks for an element that is not there
    await wait_until(lambda: master.counters.bad_frame > bad, timeout=3)
    mark = len(watch.of("odometry"))
    await watch.wait("odometry", lambda m: len(watch.of("odometry")) > mark + 3)
    last = watch.of("odometry")[-1].payload
    assert abs(last["x"]) < 0.01 and abs(last["y"]) < 0.01 and abs(last["theta"]) < 0.01


async def test_a_module_with_two_encoders_drives_both_wheels(
    onboard: Bus, channel: str, watch: Watch
) -> None:
    """One module with two motors and two PID agents (not named in wheel_sides): its first motor
    is the left wheel, the second the right; the n-th PID agent drives the n-th motor."""
    module = CustomModule(
        channel,
        0x06,
        p.Element(p.ElementKind.MOTOR, p.Role.COMPONENT),
        p.Element(p.ElementKind.MOTOR, p.Role.COMPONENT),
        p.Element(p.ElementKind.PID_VELOCITY, p.Role.AGENT, 1, 0b111),
        p.Element(p.ElementKind.PID_VELOCITY, p.Role.AGENT, 1, 0b111),
    )
    async with RoboCanStack(onboard.endpoint("robocan"), [channel], simulate=False) as stack:
        await module.start()
        try:
            await stack.wait_online({0x06})
            onboard.endpoint("navigation").publish("set_velocity", {"v": 0.2, "w": 0.5})
            await wait_until(lambda: len(module.velocity_commands) == 2)
            assert module.velocity_commands[2] == pytest.approx(0.1)  # left: v - w b / 2
            assert module.velocity_commands[3] == pytest.approx(0.3)
            for left, right in ((0, 0), (2000, 6000)):  # 0.1 m and 0.3 m at 20000 ticks/m
                module.send(p.encoder(0, left, 0.1))
                module.send(p.encoder(1, right, 0.3))
            odometry = await watch.wait("odometry", lambda m: m.payload["theta"] != 0)
            assert odometry.payload["theta"] == pytest.approx(0.5)
            assert odometry.payload["x"] == pytest.approx(0.2 * math.cos(0.25))
            base = stack.masters[0].drivers_of(BaseDriver)[0]
            assert isinstance(base, BaseDriver) and len(base.wheels) == 2
        finally:
            await module.stop()


async def test_a_module_with_two_touch_elements_numbers_its_inputs_in_order(
    onboard: Bus, channel: str, watch: Watch
) -> None:
    module = CustomModule(
        channel,
        0x44,
        p.Element(p.ElementKind.TOUCH, p.Role.COMPONENT, 3),
        p.Element(p.ElementKind.TOUCH, p.Role.COMPONENT, 3),
    )
    async with RoboCanStack(onboard.endpoint("robocan"), [channel], simulate=False) as stack:
        await module.start()
        try:
            await stack.wait_online({0x44})
            module.send(p.mask_frame(p.Op.INPUTS, 1, 0b1))  # first input of the second element
            pressed = await watch.wait("button_pressed")
            assert pressed.payload == {"button": "hand_left"}  # touch input number 3
        finally:
            await module.stop()


# --- block types ------------------------------------------------------------------------------


async def test_a_block_of_unknown_type_is_refused(stack: RoboCanStack, tap: Tap) -> None:
    master = stack.masters[0]
    errors = master.counters.block_errors
    start = len(tap.frames)
    tap.send(0x02, bytes([p.Op.BLOCK_START, 0x7E, 10, 0, 1, 2, 3, 4]))
    end = await tap.expect(0x03, p.Op.BLOCK_END, start)
    assert end == bytes([p.Op.BLOCK_END, p.EndStatus.UNKNOWN_TYPE, 0x7E])
    assert not tap.of(0x03, p.Op.BLOCK_FLOW, start)
    assert master.counters.block_errors == errors + 1
    # the simulated firmware refuses one from the master the same way
    start = len(tap.frames)
    tap.send(0x03, bytes([p.Op.BLOCK_START, 0x7E, 10, 0, 1, 2, 3, 4]))
    end = await tap.expect(0x02, p.Op.BLOCK_END, start)
    assert end == bytes([p.Op.BLOCK_END, p.EndStatus.UNKNOWN_TYPE, 0x7E])


# --- master-direction opcodes from a slave ID -------------------------------------------------


async def test_master_opcodes_from_a_slave_id_are_bad_frames(stack: RoboCanStack, tap: Tap) -> None:
    master = stack.masters[0]
    bad = master.counters.bad_frame
    tap.send(0x50, bytes([p.Op.QUERY]))  # a QUERY on an even ID: nobody's
    tap.send(0x52, p.set_velocity(1, 0.5))
    await wait_until(lambda: master.counters.bad_frame >= bad + 2, timeout=3)
    assert 0x50 not in master.modules and 0x52 not in master.modules
    errors = master.modules[0x02].errors
    tap.send(0x02, bytes([p.Op.STOP]))
    await wait_until(lambda: master.modules[0x02].errors == errors + 1, timeout=3)
    assert master.counters.bad_frame == bad + 3
