"""Simulated RoboCAN slave modules: they speak only the wire protocol, as the firmware would.

The BellBot set of the paper (motor controllers 0x02 and 0x04, sonar rings 0x10 and 0x20,
head and I/O 0x40) plus a battery monitor 0x08. Physics (distance, servo travel, battery
drain and charge) runs ``time_scale`` times faster than the wall clock; protocol timing
(watchdogs, publishing periods, time-outs) does not.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable
from typing import Any

import can

from robot_agent.robocan import protocol as p
from robot_agent.robocan.blocks import BlockReceiver, BlockSender, BlockState
from robot_agent.robocan.busopen import open_bus

__all__ = [
    "BELLBOT",
    "BatteryMonitor",
    "HeadIo",
    "MotorController",
    "SimModule",
    "Simulator",
    "SonarRing",
]

log = logging.getLogger(__name__)

TICK_S = 0.02  # physics step of the simulated firmware


class SimModule:
    """Firmware skeleton: watchdog, query/description, parameters, modes, enable, blocks."""

    description: p.Description

    def __init__(self, bus_spec: str, module_id: int, *, time_scale: float = 1.0) -> None:
        if not p.is_module_id(module_id):
            raise ValueError(f"module id 0x{module_id:X} is not an even ID in 0x02..0x7FE")
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
        self._bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._sender: BlockSender | None = None
        self._receiver: BlockReceiver | None = None
        self.running = False

    # --- life cycle -------------------------------------------------------------------

    async def start(self) -> None:
        """Power on: open the bus and start sending watchdog frames at once."""
        bus = self._bus = open_bus(self.bus_spec)
        bus.set_filters(
            [
                {"can_id": self.module_id + 1, "can_mask": 0x7FF, "extended": False},
                {"can_id": p.BROADCAST_ID, "can_mask": 0x7FF, "extended": False},
            ]
        )
        loop = asyncio.get_running_loop()
        self._notifier = can.Notifier(bus, [self._on_can], timeout=0.05, loop=loop)
        self.running = True
        self._tasks = [
            asyncio.create_task(self._watchdog_loop(), name=f"sim-wd-{self.module_id:02x}"),
            asyncio.create_task(self._physics_loop(), name=f"sim-phys-{self.module_id:02x}"),
        ]

    async def stop(self) -> None:
        """Power off (unplug): silence at once."""
        if not self.running:
            return
        self.running = False
        for task in self._tasks:
            task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError):
                await task
        if self._notifier is not None:
            await asyncio.to_thread(self._notifier.stop, 1.0)
        if self._bus is not None:
            self._bus.shutdown()

    def send(self, data: bytes) -> None:
        if not self.running or self._bus is None:
            return
        msg = can.Message(arbitration_id=self.module_id, data=data, is_extended_id=False)
        try:
            self._bus.send(msg)
            self.frames_tx += 1
        except can.CanError as exc:
            log.warning("sim 0x%02X: send failed: %s", self.module_id, exc)

    async def _watchdog_loop(self) -> None:
        while True:
            self.send(p.watchdog(self.state))
            await asyncio.sleep(self.watchdog_s)

    async def _physics_loop(self) -> None:
        last = time.monotonic()
        while True:
            await asyncio.sleep(TICK_S)
            now = time.monotonic()
            self.step(now, (now - last) * self.time_scale)
            last = now

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

    def publish_period(self, element: int, default_ms: int) -> float:
        return self.params.get((element, p.Param.PUBLISH_MS), default_ms) / 1000

    @property
    def enabled(self) -> bool:
        return self.state is p.SlaveState.ENABLED

    # --- receive path -----------------------------------------------------------------

    def _on_can(self, msg: can.Message) -> None:
        if not self.running or msg.is_extended_id or msg.is_remote_frame or msg.is_error_frame:
            return
        data = bytes(msg.data)
        try:
            op = p.check_length(data)
        except p.ProtocolError:
            return  # firmware ignores what it cannot parse
        try:
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
            self._receiver = BlockReceiver(data)
            self.send(self._receiver.first_reply())
            self._finish_block()
        elif op == p.Op.BLOCK_DATA:
            if self._receiver is not None:
                for frame in self._receiver.on_data(data):
                    self.send(frame)
                self._finish_block()
        elif op == p.Op.SET_PARAM:
            element, param, value = p.parse_set_param(data)
            status = self._set_param(element, param, value)
            self.send(p.ack(op, element, status))
        elif op == p.Op.SET_MODE:
            element, mode = data[1], data[2]
            ok = element < len(self.description.elements) and (
                self.description.elements[element].modes & (1 << mode)
            )
            if ok:
                self.modes[element] = mode
            self.send(p.ack(op, element, p.AckStatus.OK if ok else p.AckStatus.BAD_VALUE))
        elif op == p.Op.ENABLE:
            if data[1] == p.MODULE:
                self.state = p.SlaveState.ENABLED if data[2] else p.SlaveState.DISABLED
                if not data[2]:
                    self.on_stop()
            self.send(p.ack(op, data[1]))
        elif op == p.Op.MASTER_START:
            self.state = p.SlaveState.DISABLED
            self.on_stop()
        elif op == p.Op.STOP:
            self.on_stop()
        else:
            reply = self.on_command(op, data)
            if reply is not None:
                element = data[1] if len(data) > 1 and op != p.Op.SET_CHARGING else p.MODULE
                self.send(p.ack(op, element, reply))

    def _set_param(self, element: int, param: int, value: int) -> p.AckStatus:
        if element == p.MODULE:
            if param == p.Param.WATCHDOG_MS and 10 <= value <= 10000:
                self.watchdog_s = value / 1000
                return p.AckStatus.OK
            return p.AckStatus.BAD_PARAM
        if element >= len(self.description.elements):
            return p.AckStatus.UNKNOWN_ELEMENT
        if param == p.Param.PUBLISH_MS and not 10 <= value <= 60000:
            return p.AckStatus.BAD_VALUE
        status = self.on_param(element, param, value)
        if status is p.AckStatus.OK:
            self.params[(element, param)] = value
        return status

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

    def __init__(self, bus_spec: str, module_id: int, *, time_scale: float = 1.0) -> None:
        super().__init__(bus_spec, module_id, time_scale=time_scale)
        self.description = p.Description(
            kind=p.ModuleKind.MOTOR_CONTROLLER,
            name=f"motor_controller_{module_id:02x}",
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
        return self.params.get((0, p.Param.TICKS_PER_M), 20000)

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
        timeout = self.params.get((1, p.Param.COMMAND_TIMEOUT_MS), 1000) / 1000
        if self.target and now - self.last_command > timeout:
            self.target = 0.0  # the agent's own safety time-out
        accel = self.params.get((1, p.Param.MAX_ACCEL), 2000) / 1000
        change = self.target - self.velocity
        limit = accel * dt_sim
        self.velocity += max(-limit, min(limit, change))
        self.distance += self.velocity * dt_sim
        if self.enabled and now >= self.next_publish:
            self.next_publish = now + self.publish_period(0, 100)
            ticks = round(self.distance * self.ticks_per_m)
            self.send(p.encoder(0, ticks, self.velocity))

    def press_bumper(self, index: int, pressed: bool = True) -> None:
        """A physical contact (tests): the bumper frame goes out on the change."""
        self.bumpers = self.bumpers | (1 << index) if pressed else self.bumpers & ~(1 << index)
        if self.enabled:
            self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))


class SonarRing(SimModule):
    """Eight sonars with a firing-sequence agent and eight bumpers (the PIC18 module)."""

    def __init__(self, bus_spec: str, module_id: int, *, time_scale: float = 1.0) -> None:
        super().__init__(bus_spec, module_id, time_scale=time_scale)
        self.description = p.Description(
            kind=p.ModuleKind.SONAR_RING,
            name=f"sonar_ring_{module_id:02x}",
            elements=(
                p.Element(p.ElementKind.SONAR, p.Role.COMPONENT, 8),
                p.Element(p.ElementKind.FIRING_SEQUENCE, p.Role.AGENT, 1, 0b11),
                p.Element(p.ElementKind.BUMPER, p.Role.COMPONENT, 8),
            ),
        )
        self.ranges = [3.0] * 8
        self.bumpers = 0
        self.next_publish = 0.0

    def step(self, now: float, dt_sim: float) -> None:
        if self.enabled and self.modes.get(1) == 1 and now >= self.next_publish:
            self.next_publish = now + self.publish_period(0, 500)
            self.send(p.sonar(0, 0, self.ranges[:5]))
            self.send(p.sonar(0, 5, self.ranges[5:]))

    def press_bumper(self, index: int, pressed: bool = True) -> None:
        self.bumpers = self.bumpers | (1 << index) if pressed else self.bumpers & ~(1 << index)
        if self.enabled:
            self.send(p.mask_frame(p.Op.BUMPERS, 2, self.bumpers))

    @property
    def firing_sequence(self) -> bytes | None:
        return self.configs.get((1, 0))


class HeadIo(SimModule):
    """Ten RC servos, six capacitive touch inputs and four outputs (eye LEDs...)."""

    SERVOS = 10

    def __init__(self, bus_spec: str, module_id: int, *, time_scale: float = 1.0) -> None:
        super().__init__(bus_spec, module_id, time_scale=time_scale)
        self.description = p.Description(
            kind=p.ModuleKind.HEAD_IO,
            name=f"head_io_{module_id:02x}",
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
                self.speed[index] = speed or 90.0
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
    ) -> None:
        super().__init__(bus_spec, module_id, time_scale=time_scale)
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

    def step(self, now: float, dt_sim: float) -> None:
        if self.charging:
            self.level = min(1.0, self.level + self.CHARGE * dt_sim)
        else:
            moving = self.motion() > 0.01
            drain = self.MOVING_DRAIN if moving else self.IDLE_DRAIN
            self.level = max(0.0, self.level - drain * dt_sim)
        if self.enabled and now >= self.next_publish:
            self.next_publish = now + self.publish_period(0, 1000)
            self.send(p.battery(self.level, 22.0 + 4.0 * self.level, self.charging))


BELLBOT: dict[int, str] = {
    0x02: "motor",
    0x04: "motor",
    0x08: "battery",
    0x10: "sonar",
    0x20: "sonar",
    0x40: "head",
}


class Simulator:
    """The simulated robot: its modules on one virtual channel, plugged and unplugged at will."""

    def __init__(
        self,
        bus_spec: str,
        *,
        time_scale: float = 1.0,
        layout: dict[int, str] | None = None,
    ) -> None:
        self.bus_spec = bus_spec
        self.time_scale = time_scale
        self.layout = dict(BELLBOT if layout is None else layout)
        self.modules: dict[int, SimModule] = {}
        self.battery_level: float | None = None

    def _make(self, module_id: int) -> SimModule:
        kind = self.layout.get(module_id)
        kwargs: dict[str, Any] = {"time_scale": self.time_scale}
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
        for module_id in self.layout:
            await self.plug(module_id)

    async def stop(self) -> None:
        for module_id in list(self.modules):
            await self.unplug(module_id)

    async def plug(self, module_id: int) -> SimModule:
        """Power a module on (a fresh one: firmware state starts over). Idempotent."""
        module = self.modules.get(module_id)
        if module is not None:
            return module
        module = self._make(module_id)
        await module.start()
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
