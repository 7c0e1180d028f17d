"""Simulated RoboCAN slave modules: they speak only the wire protocol, as the firmware would.

The BellBot set of the paper (motor controllers 0x02 and 0x04, sonar rings 0x10 and 0x20,
head and I/O 0x40) plus a battery monitor 0x08. Physics (distance, servo travel, battery
drain and charge) runs ``time_scale`` times faster than the wall clock; protocol timing
(watchdogs, publishing periods, time-outs) does not.

The modules of one simulated robot share a ``SimHost``: one connection to the virtual bus
(one reader thread, software filtering on *M* + 1 and the broadcast ID, as each module's own
filter would) and one scheduler task. The scheduler sleeps until the next frame some module
owes (watchdog, ENCODER, SONAR, BATTERY) and runs the 50 Hz physics step only while something
moves (a wheel, a servo); a received command wakes it at once. Periodic frames fall on a grid
of their own period (multiples of it on the monotonic clock), so modules with the same period
send in the same wake-up. The frames on the wire, their lengths and rates are those of
docs/robocan.md.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Callable
from typing import Any

import can

from robot_agent.robocan import protocol as p
from robot_agent.robocan.blocks import BlockReceiver, BlockSender, BlockState
from robot_agent.robocan.busopen import BusReader, open_bus

__all__ = [
    "BELLBOT",
    "FLAWS",
    "BatteryMonitor",
    "HeadIo",
    "MotorController",
    "SimHost",
    "SimModule",
    "Simulator",
    "SonarRing",
]

log = logging.getLogger(__name__)

TICK_S = 0.02  # physics step of the simulated firmware while something moves
BLOCK_OPS = frozenset({p.Op.BLOCK_START, p.Op.BLOCK_DATA, p.Op.BLOCK_FLOW, p.Op.BLOCK_END})
FLAWS: dict[str, str] = {
    "accepts_any_value": "SET_PARAM takes values outside their range (no BAD_VALUE)",
    "no_command_timeout": "a motor keeps its last velocity when the commands stop",
    "answers_broadcast": "acts on any opcode sent to the broadcast ID 0x001",
    "no_state_on_enable": "no BUMPERS / INPUTS frame after the ACK to ENABLE",
}
"""Deliberate defects a simulated module can be built with (``flaws=``), to prove that the
conformance checks catch them."""
DUE_EPS_S = 0.001  # a frame due this close to now goes out in this wake-up


def next_slot(due: float, period: float, now: float) -> float:
    """The next send time of a periodic frame that was due at ``due``: one period later, or
    if that is already past (the first frame, a stalled process) the next multiple of the
    period after ``now``. Frames of the same period thus share wake-ups across modules."""
    following = due + period
    if following > now + DUE_EPS_S:
        return following
    return (math.floor(now / period) + 1) * period


class SimHost:
    """One virtual-bus connection and one scheduler for several simulated modules."""

    def __init__(self, bus_spec: str) -> None:
        self.bus_spec = bus_spec
        self.modules: dict[int, SimModule] = {}
        self.wakeups = 0  # scheduler wake-ups (tests, profiling)
        self._bus: can.BusABC | None = None
        self._reader: BusReader | None = None
        self._task: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._waiter: asyncio.Future[None] | None = None
        self._poked = False

    @property
    def running(self) -> bool:
        return self._task is not None

    async def start(self) -> None:
        if self._task is not None:
            return
        bus = self._bus = open_bus(self.bus_spec)
        # Slaves listen to M + 1 and the broadcast ID 0x001: odd standard IDs only.
        bus.set_filters([{"can_id": 0x001, "can_mask": 0x001, "extended": False}])
        loop = self._loop = asyncio.get_running_loop()
        self._reader = BusReader(bus, self._on_frames, loop=loop, name="sim-reader")
        self._reader.start()
        self._task = asyncio.create_task(self._run(), name="sim-host")

    async def stop(self) -> None:
        task, self._task = self._task, None
        if task is None:
            return
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
        if self._reader is not None:
            await asyncio.to_thread(self._reader.stop)
            self._reader = None
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None

    def attach(self, module: SimModule) -> None:
        self.modules[module.module_id] = module
        self.poke()

    def detach(self, module: SimModule) -> None:
        if self.modules.get(module.module_id) is module:
            del self.modules[module.module_id]

    def send(self, can_id: int, data: bytes) -> bool:
        if self._bus is None:
            return False
        msg = can.Message(arbitration_id=can_id, data=data, is_extended_id=False)
        try:
            self._bus.send(msg)
        except can.CanError as exc:
            log.warning("sim 0x%02X: send failed: %s", can_id, exc)
            return False
        return True

    def poke(self) -> None:
        """Something changed (a command, a test hook): recompute the schedule now."""
        self._poked = True
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def _on_frames(self, batch: list[can.Message]) -> None:
        for msg in batch:
            can_id = msg.arbitration_id
            if can_id == p.BROADCAST_ID:
                for module in list(self.modules.values()):
                    module._on_can(msg, broadcast=True)
            else:
                addressed = self.modules.get(can_id - 1)
                if addressed is not None:
                    addressed._on_can(msg)
        self.poke()

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            self.wakeups += 1
            self._poked = False
            now = time.monotonic()
            due = math.inf
            active = False
            for module in list(self.modules.values()):
                try:
                    module.tick(now)
                except Exception:
                    log.exception("sim 0x%02X: tick failed", module.module_id)
                due = min(due, module.next_due())
                active = active or module.active
            if active:
                due = min(due, now + TICK_S)
            if self._poked:
                continue
            waiter = self._waiter = loop.create_future()
            timer = None
            if due < math.inf:
                # loop.time() is time.monotonic(); never a past deadline (no busy loop)
                timer = loop.call_at(max(due, now + DUE_EPS_S), _wake, waiter)
            try:
                await waiter
            finally:
                self._waiter = None
                if timer is not None:
                    timer.cancel()


def _wake(waiter: asyncio.Future[None]) -> None:
    if not waiter.done():
        waiter.set_result(None)


class SimModule:
    """Firmware skeleton: watchdog, query/description, parameters, modes, enable, blocks."""

    description: p.Description

    def __init__(
        self,
        bus_spec: str,
        module_id: int,
        *,
        time_scale: float = 1.0,
        flaws: frozenset[str] = frozenset(),
    ) -> None:
        if not p.is_module_id(module_id):
            raise ValueError(f"module id 0x{module_id:X} is not an even ID in 0x02..0x7FE")
        unknown = set(flaws) - set(FLAWS)
        if unknown:
            raise ValueError(f"unknown flaws {sorted(unknown)}; known: {', '.join(FLAWS)}")
        self.flaws = frozenset(flaws)
        self.bus_spec = bus_spec
        self.module_id = module_id
        self.time_scale = time_scale
        self.state = p.SlaveState.DISABLED
        self.watchdog_s = p.WATCHDOG_PERIOD_S
        self.params: dict[tuple[int, int], int] = {}
        self.modes: dict[int, int] = {}
        self.configs: dict[tuple[int, int], bytes] = {}
        self.frames_tx = 0
        self.drop_block_frames: set[int] = set()  # fault injection: data frames never sent
        self.host: SimHost | None = None
        self._own_host = False
        self._sender: BlockSender | None = None
        self._receiver: BlockReceiver | None = None
        self._receiver_seen = 0.0  # last frame of the block being received (its time-out)
        self._last_step = 0.0
        self.next_watchdog = 0.0
        self.running = False

    # --- life cycle -------------------------------------------------------------------

    async def start(self, host: SimHost | None = None) -> None:
        """Power on: join the bus (``host``'s, or a connection of its own) and send WATCHDOG
        at once."""
        if self.running:
            return
        if host is None:
            host, self._own_host = SimHost(self.bus_spec), True
        self.host = host
        await host.start()
        self._last_step = time.monotonic()
        self.next_watchdog = 0.0  # at once
        self.running = True
        host.attach(self)

    async def stop(self) -> None:
        """Power off (unplug): silence at once."""
        if not self.running:
            return
        self.running = False
        host = self.host
        if host is not None:
            host.detach(self)
            if self._own_host:
                await host.stop()

    def send(self, data: bytes) -> None:
        if not self.running or self.host is None:
            return
        if self.host.send(self.module_id, data):
            self.frames_tx += 1

    def poke(self) -> None:
        """State changed outside a received frame (a test hook): reschedule at once."""
        if self.running and self.host is not None:
            self.host.poke()

    # --- scheduling (called by the host) ----------------------------------------------

    def tick(self, now: float) -> None:
        """Send the watchdog if due, advance the physics to ``now`` and publish what is due."""
        if now + DUE_EPS_S >= self.next_watchdog:
            self.send(p.watchdog(self.state))
            self.next_watchdog = next_slot(self.next_watchdog, self.watchdog_s, now)
        receiver = self._receiver
        if receiver is not None and now + DUE_EPS_S >= self._receiver_seen + p.BLOCK_TIMEOUT_S:
            self._receiver_seen = now  # no data frame for 250 ms: ask again, or give up
            for frame in receiver.on_timeout():
                self.send(frame)
            self._finish_block()
        self.advance(now)

    def advance(self, now: float) -> None:
        dt = now - self._last_step
        self._last_step = now
        self.step(now, max(0.0, dt) * self.time_scale)

    def next_due(self) -> float:
        """The monotonic time of the next frame this module owes without being asked."""
        if self._receiver is not None:
            return min(self.next_watchdog, self._receiver_seen + p.BLOCK_TIMEOUT_S)
        return self.next_watchdog

    @property
    def active(self) -> bool:
        """Something moves: the physics must be stepped every TICK_S."""
        return False

    def due(self, deadline: float, now: float) -> bool:
        return now + DUE_EPS_S >= deadline

    # --- what a concrete module does --------------------------------------------------

    def step(self, now: float, dt_sim: float) -> None:
        """Advance the physics by ``dt_sim`` simulated seconds and publish what is due."""

    def on_command(self, op: int, data: bytes) -> p.AckStatus | None:
        """A module-specific command; return an ACK status to acknowledge it, None for none."""
        return None

    def on_param(self, element: int, param: int, value: int) -> p.AckStatus:
        return p.AckStatus.OK

    def on_stop(self) -> None:
        """Broadcast STOP or MASTER_START: stop every actuator."""

    def on_enabled(self) -> None:
        """Just enabled (after the ACK): report the state of BUMPERS / INPUTS elements."""

    def accept_config(self, element: int, number: int, data: bytes) -> bool:
        """Judge a CONFIG block that arrived whole (False = BLOCK_END REFUSED)."""
        return False

    def param(self, element: int, param: int) -> int:
        """A parameter's value: set by the master, or its power-on default."""
        value = self.params.get((element, param))
        if value is not None:
            return value
        if param == p.Param.PUBLISH_MS:
            return p.DEFAULT_PUBLISH_MS[self.description.elements[element].kind]
        return p.PARAM_DEFAULTS.get(param, 0)

    def publish_period(self, element: int) -> float:
        return self.param(element, p.Param.PUBLISH_MS) / 1000

    @property
    def enabled(self) -> bool:
        return self.state is p.SlaveState.ENABLED

    # --- receive path -----------------------------------------------------------------

    def _on_can(self, msg: can.Message, broadcast: bool = False) -> None:
        if not self.running or msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
            return
        data = bytes(msg.data)
        try:
            op = p.check_length(data)
        except p.ProtocolError:
            return  # firmware ignores what it cannot parse
        if op not in p.MASTER_OPS and op not in BLOCK_OPS:
            return  # a slave opcode sent to a slave
        if broadcast and op not in p.BROADCAST_OPS and "answers_broadcast" not in self.flaws:
            return  # only MASTER_START and STOP are broadcast; anything else there is ignored
        try:
            self.advance(time.monotonic())  # the physics up to now, under the old command
            self._dispatch(op, data)
        except Exception:
            log.exception("sim 0x%02X: frame 0x%02X failed", self.module_id, op)

    def _dispatch(self, op: int, data: bytes) -> None:
        if op == p.Op.QUERY:
            self._sender = BlockSender(p.BlockType.DESCRIPTION, self.description.encode())
            self.send(self._sender.start())
        elif op in (p.Op.BLOCK_FLOW, p.Op.BLOCK_END):
            if self._sender is not None and self._sender.state is BlockState.ACTIVE:
                for frame in self._sender.on_frame(data):
                    if frame[1] in self.drop_block_frames:
                        self.drop_block_frames.discard(frame[1])
                        continue
                    self.send(frame)
        elif op == p.Op.BLOCK_START:
            self._receiver = BlockReceiver(
                data, types=(p.BlockType.CONFIG,), accept=self._accept_block
            )
            self._receiver_seen = time.monotonic()
            self.send(self._receiver.first_reply())
            self._finish_block()
        elif op == p.Op.BLOCK_DATA:
            if self._receiver is not None:
                self._receiver_seen = time.monotonic()
                for frame in self._receiver.on_data(data):
                    self.send(frame)
                self._finish_block()
        elif op == p.Op.SET_PARAM:
            element, param, value = p.parse_set_param(data)
            status = self._set_param(element, param, value)
            self.send(p.ack(op, element, status))
        elif op == p.Op.SET_MODE:
            element, mode = data[1], data[2]
            status = self._set_mode(element, mode)
            if status is p.AckStatus.OK:
                self.modes[element] = mode
            self.send(p.ack(op, element, status))
        elif op == p.Op.ENABLE:
            self._enable(data[1], data[2])
        elif op == p.Op.MASTER_START:
            self.state = p.SlaveState.DISABLED
            self.on_stop()
        elif op == p.Op.STOP:
            self.on_stop()
        elif op == p.Op.SET_CHARGING:
            reply = self.on_command(op, data)
            self.send(p.ack(op, p.MODULE, p.AckStatus.UNSUPPORTED if reply is None else reply))
        else:
            self.on_command(op, data)  # actuator commands are not acknowledged

    def _enable(self, element: int, on: int) -> None:
        """ENABLE of the module; one element alone is not supported by our firmware."""
        if element != p.MODULE:
            known = element < len(self.description.elements)
            status = p.AckStatus.UNSUPPORTED if known else p.AckStatus.UNKNOWN_ELEMENT
            self.send(p.ack(p.Op.ENABLE, element, status))
            return
        self.state = p.SlaveState.ENABLED if on else p.SlaveState.DISABLED
        if not on:
            self.on_stop()
        self.send(p.ack(p.Op.ENABLE, element))
        if on and "no_state_on_enable" not in self.flaws:
            self.on_enabled()

    def _set_mode(self, element: int, mode: int) -> p.AckStatus:
        if element >= len(self.description.elements):
            return p.AckStatus.UNKNOWN_ELEMENT
        modes = self.description.elements[element].modes
        if not modes:
            return p.AckStatus.UNSUPPORTED
        return p.AckStatus.OK if mode < 8 and modes & (1 << mode) else p.AckStatus.BAD_VALUE

    def _set_param(self, element: int, param: int, value: int) -> p.AckStatus:
        if element == p.MODULE:
            if param != p.Param.WATCHDOG_MS:
                return p.AckStatus.BAD_PARAM
            low, high = p.PARAM_RANGES[param]
            if not low <= value <= high:
                return p.AckStatus.BAD_VALUE
            self.watchdog_s = value / 1000
            return p.AckStatus.OK
        if element >= len(self.description.elements):
            return p.AckStatus.UNKNOWN_ELEMENT
        if param not in p.ELEMENT_PARAMS.get(self.description.elements[element].kind, ()):
            return p.AckStatus.BAD_PARAM
        low, high = p.PARAM_RANGES[param]
        if not low <= value <= high and "accepts_any_value" not in self.flaws:
            return p.AckStatus.BAD_VALUE
        status = self.on_param(element, param, value)
        if status is p.AckStatus.OK:
            self.params[(element, param)] = value
        return status

    def _accept_block(self, block_type: int, data: bytes) -> bool:
        return len(data) >= 2 and self.accept_config(data[0], data[1], data[2:])

    def _finish_block(self) -> None:
        receiver = self._receiver
        if receiver is None or receiver.state is BlockState.ACTIVE:
            return
        self._receiver = None
        if receiver.state is BlockState.DONE and receiver.block_type == p.BlockType.CONFIG:
            data = receiver.data
            if len(data) >= 2:
                self.configs[(data[0], data[1])] = data[2:]


class MotorController(SimModule):
    """Motor + encoder, a velocity PID agent and four bumpers (the paper's dsPIC module)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """As ``SimModule`` (bus_spec, module_id, time_scale=, flaws=)."""
        super().__init__(*args, **kwargs)
        self.description = p.Description(
            kind=p.ModuleKind.MOTOR_CONTROLLER,
            name=f"motor_controller_{self.module_id:02x}",
            firmware=(2, 1),
            elements=(
                p.Element(p.ElementKind.MOTOR, p.Role.COMPONENT),
                p.Element(p.ElementKind.PID_VELOCITY, p.Role.AGENT, 1, 0b111),
                p.Element(p.ElementKind.BUMPER, p.Role.COMPONENT, 4),
            ),
        )
        self.target = 0.0
        self.velocity = 0.0
        self.distance = 0.0
        self.last_command = 0.0
        self.next_publish = 0.0
        self.bumpers = 0
        self.commands = 0

    @property
    def ticks_per_m(self) -> int:
        return self.param(0, p.Param.TICKS_PER_M)

    def on_command(self, op: int, data: bytes) -> p.AckStatus | None:
        if op == p.Op.SET_VELOCITY:
            _, velocity, _ = p.parse_set_velocity(data)
            self.commands += 1
            if self.enabled and self.modes.get(1) == 1:
                self.target = velocity
                self.last_command = time.monotonic()
        return None  # velocity commands are not acknowledged: the next one follows soon

    def on_stop(self) -> None:
        self.target = 0.0
        self.velocity = 0.0

    def step(self, now: float, dt_sim: float) -> None:
        timeout = self.param(1, p.Param.COMMAND_TIMEOUT_MS) / 1000
        timed_out = now - self.last_command > timeout and "no_command_timeout" not in self.flaws
        if self.target and timed_out:
            self.target = 0.0  # the agent's own safety time-out
        accel = self.param(1, p.Param.MAX_ACCEL) / 1000
        change = self.target - self.velocity
        limit = accel * dt_sim
        self.velocity += max(-limit, min(limit, change))
        self.distance += self.velocity * dt_sim
        if self.enabled and self.due(self.next_publish, now):
            self.next_publish = next_slot(self.next_publish, self.publish_period(0), now)
            ticks = round(self.distance * self.ticks_per_m)
            self.send(p.encoder(0, ticks, self.velocity))

    @property
    def active(self) -> bool:
        return bool(self.target or self.velocity)

    def next_due(self) -> float:
        due = super().next_due()
        return min(due, self.next_publish) if self.enabled else due

    def press_bumper(self, index: int, pressed: bool = True) -> None:
        """A physical contact (tests): the bumper frame goes out on the change, and a new
        contact stops this controller's motor by itself (it does not wait for the master)."""
        if pressed and not self.bumpers & (1 << index):
            self.target = 0.0
        self.bumpers = self.bumpers | (1 << index) if pressed else self.bumpers & ~(1 << index)
        if self.enabled:
            self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))

    def on_enabled(self) -> None:
        self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))


class SonarRing(SimModule):
    """Sonars (eight by default) with a firing-sequence agent and eight bumpers (the PIC18
    module). It fires the sonars its firing order lists (all of them, in index order, until
    the master sends one); a sonar it does not fire reports 255, nothing in range."""

    def __init__(
        self,
        bus_spec: str,
        module_id: int,
        *,
        time_scale: float = 1.0,
        sonars: int = 8,
        flaws: frozenset[str] = frozenset(),
    ) -> None:
        super().__init__(bus_spec, module_id, time_scale=time_scale, flaws=flaws)
        self.description = p.Description(
            kind=p.ModuleKind.SONAR_RING,
            name=f"sonar_ring_{module_id:02x}",
            elements=(
                p.Element(p.ElementKind.SONAR, p.Role.COMPONENT, sonars),
                p.Element(p.ElementKind.FIRING_SEQUENCE, p.Role.AGENT, 1, 0b11),
                p.Element(p.ElementKind.BUMPER, p.Role.COMPONENT, 8),
            ),
        )
        self.ranges: list[float | None] = [3.0] * sonars
        self.bumpers = 0
        self.next_publish = 0.0

    @property
    def firing(self) -> bool:
        return self.enabled and self.modes.get(1) == 1

    def accept_config(self, element: int, number: int, data: bytes) -> bool:
        """Config 0 of the firing agent: each sonar index at most once, all of them real."""
        count = len(self.ranges)
        return (
            element == 1
            and number == 0
            and 1 <= len(data) <= count
            and len(set(data)) == len(data)
            and max(data) < count
        )

    def step(self, now: float, dt_sim: float) -> None:
        if self.firing and self.due(self.next_publish, now):
            self.next_publish = next_slot(self.next_publish, self.publish_period(0), now)
            order = self.firing_sequence
            fired = set(order) if order is not None else set(range(len(self.ranges)))
            values = [r if i in fired else None for i, r in enumerate(self.ranges)]
            for first in range(0, len(values), 5):
                self.send(p.sonar(0, first, values[first : first + 5]))

    def next_due(self) -> float:
        due = super().next_due()
        return min(due, self.next_publish) if self.firing else due

    def press_bumper(self, index: int, pressed: bool = True) -> None:
        self.bumpers = self.bumpers | (1 << index) if pressed else self.bumpers & ~(1 << index)
        if self.enabled:
            self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))

    def on_enabled(self) -> None:
        self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))

    @property
    def firing_sequence(self) -> bytes | None:
        return self.configs.get((1, 0))


class HeadIo(SimModule):
    """Ten RC servos, six capacitive touch inputs and four outputs (eye LEDs...)."""

    SERVOS = 10
    TOP_SPEED = 360.0  # degrees/s: what SET_SERVO speed 0 means on this module

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        """As ``SimModule`` (bus_spec, module_id, time_scale=, flaws=)."""
        super().__init__(*args, **kwargs)
        self.description = p.Description(
            kind=p.ModuleKind.HEAD_IO,
            name=f"head_io_{self.module_id:02x}",
            elements=(
                p.Element(p.ElementKind.SERVO, p.Role.COMPONENT, self.SERVOS),
                p.Element(p.ElementKind.TOUCH, p.Role.COMPONENT, 6),
                p.Element(p.ElementKind.LED, p.Role.COMPONENT, 4),
            ),
        )
        self.position = [0.0] * self.SERVOS
        self.target = [0.0] * self.SERVOS
        self.speed = [90.0] * self.SERVOS
        self.next_publish = [0.0] * self.SERVOS
        self.report = [False] * self.SERVOS
        self.touch_mask = 0
        self.outputs = [0] * 4

    def on_command(self, op: int, data: bytes) -> p.AckStatus | None:
        if op == p.Op.SET_SERVO and self.enabled:
            _, index, position, speed = p.parse_set_servo(data)
            if index < self.SERVOS:
                self.target[index] = position
                self.speed[index] = speed or self.TOP_SPEED  # 0 = as fast as it goes
                self.next_publish[index] = 0.0
                self.report[index] = True  # confirmed even when it is already there
        elif op == p.Op.SET_OUTPUT and self.enabled:
            if data[2] < len(self.outputs):
                self.outputs[data[2]] = data[3]
        return None

    def step(self, now: float, dt_sim: float) -> None:
        for i in range(self.SERVOS):
            if self.position[i] == self.target[i]:
                if self.report[i] and self.enabled:
                    self.report[i] = False
                    self.send(p.servo(0, i, self.position[i], True))
                continue
            move = self.speed[i] * dt_sim
            gap = self.target[i] - self.position[i]
            self.position[i] = (
                self.target[i]
                if abs(gap) <= move
                else self.position[i] + (move if gap > 0 else -move)
            )
            arrived = self.position[i] == self.target[i]
            if arrived:
                self.report[i] = False
            if self.enabled and (arrived or now >= self.next_publish[i]):
                self.next_publish[i] = now + 0.1
                self.send(p.servo(0, i, self.position[i], arrived))

    @property
    def active(self) -> bool:
        moving = any(pos != target for pos, target in zip(self.position, self.target, strict=True))
        return moving or (self.enabled and any(self.report))

    def on_enabled(self) -> None:
        self.send(p.mask_frame(p.Op.INPUTS, 1, self.touch_mask))

    def touch(self, index: int, pressed: bool = True) -> None:
        self.touch_mask = (
            self.touch_mask | (1 << index) if pressed else self.touch_mask & ~(1 << index)
        )
        if self.enabled:
            self.send(p.mask_frame(p.Op.INPUTS, 1, self.touch_mask))


class BatteryMonitor(SimModule):
    """Battery level and charger contact. Drains while the base moves, charges when docked."""

    IDLE_DRAIN = 1 / (8 * 3600)  # per simulated second
    MOVING_DRAIN = 1 / (2 * 3600)
    CHARGE = 1 / 3600

    def __init__(
        self,
        bus_spec: str,
        module_id: int,
        *,
        time_scale: float = 1.0,
        motion: Callable[[], float] = lambda: 0.0,
        flaws: frozenset[str] = frozenset(),
    ) -> None:
        super().__init__(bus_spec, module_id, time_scale=time_scale, flaws=flaws)
        self.description = p.Description(
            kind=p.ModuleKind.BATTERY_MONITOR,
            name=f"battery_{module_id:02x}",
            elements=(p.Element(p.ElementKind.BATTERY, p.Role.COMPONENT),),
        )
        self.level = 1.0
        self.charging = False
        self.motion = motion
        self.next_publish = 0.0

    def on_command(self, op: int, data: bytes) -> p.AckStatus | None:
        if op == p.Op.SET_CHARGING:
            self.charging = bool(data[1])
            self.next_publish = 0.0  # report the new state at once
            return p.AckStatus.OK
        return None

    def set_level(self, level: float) -> None:
        self.level = max(0.0, min(1.0, level))
        self.next_publish = 0.0
        self.poke()

    def step(self, now: float, dt_sim: float) -> None:
        if self.charging:
            self.level = min(1.0, self.level + self.CHARGE * dt_sim)
        else:
            moving = self.motion() > 0.01
            drain = self.MOVING_DRAIN if moving else self.IDLE_DRAIN
            self.level = max(0.0, self.level - drain * dt_sim)
        if self.enabled and self.due(self.next_publish, now):
            self.next_publish = next_slot(self.next_publish, self.publish_period(0), now)
            self.send(p.battery(self.level, 22.0 + 4.0 * self.level, self.charging))

    def next_due(self) -> float:
        due = super().next_due()
        return min(due, self.next_publish) if self.enabled else due


BELLBOT: dict[int, str] = {
    0x02: "motor",
    0x04: "motor",
    0x08: "battery",
    0x10: "sonar",
    0x20: "sonar",
    0x40: "head",
}


class Simulator:
    """The simulated robot: its modules on one virtual channel, plugged and unplugged at will.
    They share one ``SimHost`` (bus connection and scheduler)."""

    def __init__(
        self,
        bus_spec: str,
        *,
        time_scale: float = 1.0,
        layout: dict[int, str] | None = None,
        flaws: dict[int, frozenset[str]] | None = None,
    ) -> None:
        self.bus_spec = bus_spec
        self.time_scale = time_scale
        self.layout = dict(BELLBOT if layout is None else layout)
        self.flaws = dict(flaws or {})
        self.modules: dict[int, SimModule] = {}
        self.battery_level: float | None = None
        self.host = SimHost(bus_spec)

    def _make(self, module_id: int) -> SimModule:
        kind = self.layout.get(module_id)
        kwargs: dict[str, Any] = {
            "time_scale": self.time_scale,
            "flaws": self.flaws.get(module_id, frozenset()),
        }
        if kind == "motor":
            return MotorController(self.bus_spec, module_id, **kwargs)
        if kind == "sonar":
            return SonarRing(self.bus_spec, module_id, **kwargs)
        if kind == "head":
            return HeadIo(self.bus_spec, module_id, **kwargs)
        if kind == "battery":
            module = BatteryMonitor(self.bus_spec, module_id, motion=self.motion, **kwargs)
            if self.battery_level is not None:
                module.level = self.battery_level
            return module
        raise KeyError(f"no simulated module 0x{module_id:02X} in this robot's layout")

    def motion(self) -> float:
        return sum(abs(m.velocity) for m in self.modules.values() if isinstance(m, MotorController))

    async def start(self) -> None:
        await self.host.start()
        for module_id in self.layout:
            await self.plug(module_id)

    async def stop(self) -> None:
        for module_id in list(self.modules):
            await self.unplug(module_id)
        await self.host.stop()

    async def plug(self, module_id: int) -> SimModule:
        """Power a module on (a fresh one: firmware state starts over). Idempotent."""
        module = self.modules.get(module_id)
        if module is not None:
            return module
        module = self._make(module_id)
        await module.start(self.host)
        self.modules[module_id] = module
        return module

    async def unplug(self, module_id: int) -> None:
        module = self.modules.pop(module_id, None)
        if module is not None:
            if isinstance(module, BatteryMonitor):
                self.battery_level = module.level
            await module.stop()

    def set_battery_level(self, level: float) -> None:
        self.battery_level = level
        for module in self.modules.values():
            if isinstance(module, BatteryMonitor):
                module.set_level(level)
