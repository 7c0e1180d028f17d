"""The simulated firmware's scheduler, driven with explicit times (no sleeps): what an idle
module owes and when, shared wake-ups, physics only while something moves; the bus reader's
batches."""

from __future__ import annotations

import asyncio
import threading
import time

import can
import pytest

from robot_agent.robocan import protocol as p
from robot_agent.robocan.busopen import BusReader, open_bus
from robot_agent.robocan.sim import HeadIo, MotorController, SimBattery, SimModule, SonarRing
from robot_agent.robocan.sim.host import TICK_S, next_slot


class Recorder:
    """Stands in for the host: records what a module sends, at which (given) time."""

    def __init__(self) -> None:
        self.sent: list[tuple[int, bytes]] = []

    def send(self, can_id: int, data: bytes) -> bool:
        self.sent.append((can_id, data))
        return True

    def poke(self) -> None:
        pass

    def ops(self) -> list[int]:
        """Opcodes sent (a watchdog as WATCHDOG, whatever its state nibble)."""
        return [data[0] if data[0] > 0x0F else p.Op.WATCHDOG for _, data in self.sent]


def powered(module: SimModule, now: float) -> Recorder:
    """A module powered on at ``now`` on a recording host, enabled as the master would."""
    recorder = Recorder()
    module.host = recorder  # type: ignore[assignment]
    module.running = True
    module._last_step = now
    module.state = p.SlaveState.ENABLED
    return recorder


def command(module: SimModule, data: bytes) -> None:
    module._dispatch(p.check_length(data), data)


def test_next_slot_keeps_the_period_and_realigns_after_a_gap() -> None:
    assert next_slot(5.1, 0.1, 5.1004) == pytest.approx(5.2)
    assert next_slot(0.0, 0.1, 5.03) == pytest.approx(5.1)  # first frame: onto the grid
    assert next_slot(5.1, 0.1, 7.33) == pytest.approx(7.4)  # a stalled process: no burst
    assert next_slot(0.0, 0.5, 5.03) == pytest.approx(5.5)


def test_idle_motor_owes_only_its_watchdog_and_encoder() -> None:
    motor = MotorController("virtual:x", 0x02)
    sent = powered(motor, 100.0)
    motor.modes[1] = 1
    motor.tick(100.03)
    assert sent.ops() == [p.Op.WATCHDOG, p.Op.ENCODER]  # both at once after power-on
    assert not motor.active  # stopped: no physics steps
    assert motor.next_due() == pytest.approx(100.1)  # both on the 100 ms grid
    motor.tick(100.06)  # an early wake-up sends nothing
    assert len(sent.sent) == 2
    motor.tick(motor.next_due())
    assert sent.ops()[2:] == [p.Op.WATCHDOG, p.Op.ENCODER]
    assert motor.next_due() == pytest.approx(100.2)


def test_a_velocity_command_starts_the_physics_and_stopping_ends_it() -> None:
    motor = MotorController("virtual:x", 0x02)
    powered(motor, 100.0)
    motor.modes[1] = 1
    motor.tick(100.0)
    command(motor, p.set_velocity(1, 0.5))
    assert motor.active
    now = 100.0
    while motor.velocity < 0.5:
        now += TICK_S
        motor.tick(now)
    assert motor.distance > 0
    command(motor, p.set_velocity(1, 0.0))
    while motor.velocity > 0:
        now += TICK_S
        motor.tick(now)
    assert not motor.active
    # an idle stretch of any length moves nothing
    distance = motor.distance
    motor.tick(now + 30.0)
    assert motor.distance == distance


def test_a_stall_of_the_process_does_not_trip_the_motors_command_timeout() -> None:
    """The process stands still 1.5 s (the 1 s time-out's worth and more): the agent's next
    command is late because of it, not lost, so the wheels go on; real silence still stops
    them. On the real clock, as the simulator runs."""
    motor = MotorController("virtual:x", 0x02)
    start = time.monotonic()
    powered(motor, start)
    motor.modes[1] = 1
    motor.tick(start)
    command(motor, p.set_velocity(1, 0.5))
    now = start + 1.5
    motor.tick(now)
    assert motor.target == 0.5
    while motor.target and now < start + 5.0:
        now += TICK_S
        motor.tick(now)
    assert motor.target == 0.0 and 2.35 <= now - start <= 2.5  # 1 s of it counted


def test_modules_of_one_robot_share_their_wake_ups() -> None:
    """Watchdogs and data frames fall on their period's grid: one wake-up serves them all."""
    modules: list[SimModule] = [
        MotorController("virtual:x", 0x02),
        SonarRing("virtual:x", 0x10),
        HeadIo("virtual:x", 0x40),
        SimBattery("virtual:x", 0x08),
    ]
    for start, module in zip((10.013, 10.041, 10.077, 10.09), modules, strict=True):
        powered(module, start)
        module.modes[1] = 1
        module.tick(start)  # powered on at different times: first watchdog at once
    dues = {round(m.next_due(), 6) for m in modules}
    assert dues == {10.1}
    for module in modules:
        module.tick(10.1)
    assert {round(m.next_due(), 6) for m in modules} == {10.2}
    assert not any(m.active for m in modules)


def test_a_moving_servo_needs_the_physics_until_it_reports_arrival() -> None:
    head = HeadIo("virtual:x", 0x40)
    sent = powered(head, 50.0)
    head.tick(50.0)
    command(head, p.set_servo(0, 3, 9.0, 90.0))
    assert head.active
    now = 50.0
    for _ in range(100):
        if not head.active:
            break
        now += TICK_S
        head.tick(now)
    assert not head.active
    servo = [p.parse_servo(d) for _, d in sent.sent if d[0] == p.Op.SERVO]
    assert servo[-1] == (0, 3, pytest.approx(9.0), True)


def test_battery_drains_over_an_idle_stretch_without_being_stepped() -> None:
    battery = SimBattery("virtual:x", 0x08)
    sent = powered(battery, 0.0)
    battery.tick(0.0)
    battery.tick(3600.0)  # an hour later, in one step
    assert battery.level == pytest.approx(1 - 1 / 8)
    assert sent.ops().count(p.Op.BATTERY) == 2


def test_bus_reader_hands_a_burst_over_as_one_batch() -> None:
    channel = f"virtual:test-reader-{time.monotonic_ns()}"
    bus, sender = open_bus(channel), open_bus(channel)
    batches: list[list[can.Message]] = []
    got = threading.Event()

    def on_batch(batch: list[can.Message]) -> None:
        batches.append(batch)
        got.set()

    try:
        for i in range(5):  # queued before the reader runs: one burst
            sender.send(can.Message(arbitration_id=0x02, data=bytes([i]), is_extended_id=False))
        reader = BusReader(bus, on_batch)
        reader.start()
        assert got.wait(5)
        reader.stop()
    finally:
        bus.shutdown()
        sender.shutdown()
    assert [[m.data[0] for m in b] for b in batches] == [[0, 1, 2, 3, 4]]


async def test_bus_reader_delivers_in_the_event_loop() -> None:
    channel = f"virtual:test-reader-{time.monotonic_ns()}"
    bus, sender = open_bus(channel), open_bus(channel)
    loop = asyncio.get_running_loop()
    arrived: asyncio.Future[threading.Thread] = loop.create_future()
    reader = BusReader(bus, lambda batch: arrived.set_result(threading.current_thread()), loop=loop)
    reader.start()
    try:
        sender.send(can.Message(arbitration_id=0x02, data=b"\x00", is_extended_id=False))
        assert await asyncio.wait_for(arrived, 5) is threading.main_thread()
    finally:
        await asyncio.to_thread(reader.stop)
        bus.shutdown()
        sender.shutdown()
