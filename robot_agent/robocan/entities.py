"""Built-in drivers and the entities they serve on the on-board bus (RoboCAN paper, Figure 5):
base (velocity commands, odometry), bumpers, sonar, head servos, touch inputs and LEDs, battery.

Each class is registered under its element kinds in the built-in table
(``drivers.BUILTIN_DRIVERS``); message names and fields are those of docs/messages.md. The six
drivers stay in one file (about 500 lines) as the one table of what the robot's hardware says
on board; the base driver, the largest, is a third of it.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import logging
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from guidebot.messages import Message
from guidebot.payloads.petri import ServoInPosition
from guidebot.payloads.robot import BatteryAlarm
from robot_agent.robocan import protocol as p
from robot_agent.robocan.drivers import Driver

if TYPE_CHECKING:
    from robot_agent.robocan.master import Module

__all__ = [
    "BaseDriver",
    "BatteryDriver",
    "BumperDriver",
    "HeadDriver",
    "IoDriver",
    "SonarDriver",
]

log = logging.getLogger(__name__)


def _number(payload: dict[str, Any], key: str, default: float = 0.0) -> float:
    value = payload.get(key, default)
    if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
        raise ValueError(f"{key} must be a finite number, got {value!r}")
    return float(value)


@dataclass
class Sample:
    """One ENCODER frame of a wheel: when it arrived, the travel since the previous one."""

    time: float
    delta_m: float
    velocity: float


PENDING_MAX = 64
"""Samples a wheel keeps waiting for the other wheel's (a stalled master drains one ID's queue
before the next: up to 16 at once); older ones are folded into the next."""


@dataclass
class Wheel:
    side: str
    pid_element: int | None = None
    last_ticks: int | None = None
    pending: collections.deque[Sample] = field(default_factory=collections.deque)
    """Samples not yet paired with the other wheel's sample of the same period."""
    carry_m: float = 0.0
    """Travel of samples that found no partner, added to this wheel's next sample."""
    online: bool = False

    def add(self, sample: Sample) -> None:
        sample.delta_m += self.carry_m
        self.carry_m = 0.0
        self.pending.append(sample)
        if len(self.pending) > PENDING_MAX:
            self.fold()

    def fold(self) -> None:
        """The oldest sample has no partner: its travel goes with the next one."""
        self.carry_m += self.pending.popleft().delta_m
        if self.pending:
            self.pending[0].delta_m += self.carry_m
            self.carry_m = 0.0

    def reset(self) -> None:
        self.last_ticks = None
        self.pending.clear()
        self.carry_m = 0.0


class BaseDriver(Driver):
    """Differential base: two wheels, each a motor element (motor + encoder) driven by a PID
    velocity agent. The n-th PID agent of a module drives its n-th motor.

    Which wheel is which (docs/robocan.md, section 8): ``DriverConfig.wheel_sides`` names the
    side of a module's first motor (0x02 left, 0x04 right); a module it does not name that has
    two motors drives both, its first motor the left wheel. Any other motor is not a wheel.

    Critical: losing a motor controller stops the base and publishes ``base_fault``. While
    the base moves the last command is repeated every ``command_period_s`` (8 Hz); while it is
    stopped no velocity frame is sent (the paper's stopped-state saving).
    """

    kinds = ("pid_velocity", "motor")
    critical = True

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.wheels: dict[tuple[int, int], Wheel] = {}  # (module id, motor element) -> wheel
        self.target = (0.0, 0.0)
        self.x = self.y = self.theta = 0.0
        self.faults: set[int] = set()
        self._repeat: asyncio.Task[None] | None = None

    def start(self) -> None:
        self._unsubscribe.append(self.endpoint.subscribe("set_velocity", self._on_set_velocity))

    def close(self) -> None:
        super().close()
        if self._repeat is not None:
            self._repeat.cancel()

    def _side(self, module: Module, nth: int, motors: int) -> str | None:
        side = self.config.wheel_sides.get(module.module_id)
        if side is not None:
            return side if nth == 0 else None
        if motors == 2:
            return ("left", "right")[nth]
        return None

    async def configure(self, module: Module, index: int, element: p.Element) -> None:
        mid = module.module_id
        assert module.description is not None
        if element.kind == p.ElementKind.MOTOR:
            motors = list(module.description.numbering(p.ElementKind.MOTOR))
            pids = list(module.description.numbering(p.ElementKind.PID_VELOCITY))
            nth = motors.index(index)
            side = self._side(module, nth, len(motors))
            taken = [
                key
                for key, w in self.wheels.items()
                if w.side == side and key[0] != mid and w.online
            ]
            if side is None or taken:
                log.warning(
                    "robocan: motor element %d of 0x%02X is not a wheel (%s)",
                    index,
                    mid,
                    "its side is taken" if taken else "no side in wheel_sides",
                )
            else:
                for key in [k for k, w in self.wheels.items() if w.side == side]:
                    del self.wheels[key]
                pid = pids[nth] if nth < len(pids) else None
                self.wheels[(mid, index)] = Wheel(side, pid)
            await self.master.command(
                mid, p.set_param(index, p.Param.PUBLISH_MS, self.config.encoder_period_ms)
            )
            await self.master.command(
                mid, p.set_param(index, p.Param.TICKS_PER_M, self.config.ticks_per_m)
            )
        else:
            timeout_ms = round(p.MOTOR_COMMAND_TIMEOUT_S * 1000)
            await self.master.command(
                mid, p.set_param(index, p.Param.COMMAND_TIMEOUT_MS, timeout_ms)
            )
            await self.master.command(mid, p.set_mode(index, 1))  # 1 = velocity control

    def _wheels_of(self, module: Module) -> list[Wheel]:
        return [w for (mid, _), w in self.wheels.items() if mid == module.module_id]

    def on_online(self, module: Module) -> None:
        for wheel in self._wheels_of(module):
            wheel.online = True
            wheel.reset()
        self.faults.discard(module.module_id)

    def on_lost(self, module: Module, reason: str) -> None:
        for wheel in self._wheels_of(module):
            wheel.online = False
        self.faults.add(module.module_id)
        self.stop()
        self.endpoint.publish(
            "base_fault",
            {"reason": f"motor controller 0x{module.module_id:02X} ({module.name}) lost: {reason}"},
        )

    @property
    def faulted(self) -> bool:
        return bool(self.faults)

    # --- commands ---------------------------------------------------------------------

    def _on_set_velocity(self, message: Message) -> None:
        try:
            v = _number(message.payload, "v")
            w = _number(message.payload, "w")
        except ValueError as exc:
            log.warning("robocan: set_velocity refused: %s", exc)
            return
        if self.faulted and (v or w):
            log.warning("robocan: set_velocity ignored, base fault on %s", sorted(self.faults))
            return
        self.target = (v, w)
        self.send_velocity()
        moving = bool(v or w)
        if moving and (self._repeat is None or self._repeat.done()):
            self._repeat = asyncio.get_running_loop().create_task(self._repeat_commands())
        elif not moving and self._repeat is not None:
            self._repeat.cancel()
            self._repeat = None

    def send_velocity(self) -> None:
        """One velocity frame per wheel, from the current (v, w)."""
        v, w = self.target
        half = w * self.config.wheel_base_m / 2
        for (mid, _), wheel in self.wheels.items():
            if wheel.online and wheel.pid_element is not None:
                speed = v - half if wheel.side == "left" else v + half
                self.master.send_to(mid, p.set_velocity(wheel.pid_element, speed))

    async def _repeat_commands(self) -> None:
        # Deadline-based so that the rate stays at 8 Hz however late one wake-up is.
        loop = asyncio.get_running_loop()
        period = self.config.command_period_s
        deadline = loop.time()
        with contextlib.suppress(asyncio.CancelledError):
            while True:
                deadline += period
                await asyncio.sleep(max(0.0, deadline - loop.time()))
                self.send_velocity()

    def stop(self) -> None:
        """Stop the base at once: zero velocity to every controller and a broadcast STOP."""
        self.target = (0.0, 0.0)
        if self._repeat is not None:
            self._repeat.cancel()
            self._repeat = None
        self.send_velocity()
        self.master.send(p.BROADCAST_ID, bytes([p.Op.STOP]))

    # --- odometry ---------------------------------------------------------------------

    def on_frame(self, module: Module, element: int, data: bytes) -> None:
        wheel = self.wheels.get((module.module_id, element))
        if wheel is None:
            return  # a motor that is not a wheel
        _, ticks, velocity = p.parse_encoder(data)
        delta = 0.0
        if wheel.last_ticks is not None:
            delta = (((ticks - wheel.last_ticks + 2**31) % 2**32) - 2**31) / self.config.ticks_per_m
        wheel.last_ticks = ticks
        wheel.add(Sample(module.frame_time, delta, velocity))
        self._pair()

    def _pair(self) -> None:
        """Odometry from the two wheels' samples of one period: paired by when they arrived
        (within half an encoder period), never by the order the master handles them in. A
        master back from a stall handles one module's queued frames before the next module's,
        and a wheel that comes online after the other starts between two of its frames: "the
        next frame of each" then paired one wheel's period with the other's previous one for
        good. A sample without a partner (the other wheel's frame lost, or not online) adds
        its travel to its wheel's next sample: the encoder ticks count on meanwhile."""
        sides = {w.side: w for w in self.wheels.values() if w.online}
        left, right = sides.get("left"), sides.get("right")
        if left is None or right is None:
            for wheel in sides.values():  # nothing to pair with: keep only the latest
                while len(wheel.pending) > 1:
                    wheel.fold()
            return
        tolerance = self.config.encoder_period_ms / 2000
        while left.pending and right.pending:
            a, b = left.pending[0], right.pending[0]
            if abs(a.time - b.time) > tolerance:
                (left if a.time < b.time else right).fold()
                continue
            left.pending.popleft()
            right.pending.popleft()
            self._integrate(a, b)

    def _integrate(self, left: Sample, right: Sample) -> None:
        base = self.config.wheel_base_m
        ds = (left.delta_m + right.delta_m) / 2
        dtheta = (right.delta_m - left.delta_m) / base
        self.x += ds * math.cos(self.theta + dtheta / 2)
        self.y += ds * math.sin(self.theta + dtheta / 2)
        self.theta = math.remainder(self.theta + dtheta, math.tau)
        self.endpoint.publish(
            "odometry",
            {
                "x": self.x,
                "y": self.y,
                "theta": self.theta,
                "v": (left.velocity + right.velocity) / 2,
                "w": (right.velocity - left.velocity) / base,
            },
        )


def _instance(module: Module, kind: int, element: int, index: int) -> int:
    """The module-wide number of instance ``index`` of ``element`` (instances of one kind are
    numbered across the module's elements of that kind); ProtocolError when out of range."""
    assert module.description is not None
    first, count = module.description.numbering(kind)[element]
    if index >= count:
        raise p.ProtocolError(f"element {element} has {count} instances, frame names {index}")
    return first + index


def _new_bits(module: Module, kind: int, element: int, mask: int, old: int) -> list[int]:
    """Module-wide numbers of the bits set in ``mask`` and not in ``old``; a mask with a bit
    beyond the element's count is a ProtocolError (a bad frame)."""
    assert module.description is not None
    first, count = module.description.numbering(kind)[element]
    if mask >> count:
        raise p.ProtocolError(f"element {element} has {count} inputs, mask 0x{mask:04X}")
    pressed = mask & ~old
    return [first + bit for bit in range(count) if pressed & (1 << bit)]


class BumperDriver(Driver):
    """Bumpers on the sonar rings and motor controllers: a new contact stops the base."""

    kinds = ("bumper",)

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.masks: dict[tuple[int, int], int] = {}  # (module id, element) -> mask

    def on_online(self, module: Module) -> None:
        for key in [k for k in self.masks if k[0] == module.module_id]:
            del self.masks[key]

    def on_frame(self, module: Module, element: int, data: bytes) -> None:
        _, mask = p.parse_mask(data)
        key = (module.module_id, element)
        hits = _new_bits(module, p.ElementKind.BUMPER, element, mask, self.masks.get(key, 0))
        self.masks[key] = mask
        if not hits:
            return
        for base in self.master.drivers_of(BaseDriver):
            assert isinstance(base, BaseDriver)
            base.stop()
        ring = self.config.bumper_rings.get(module.module_id, module.module_id)
        for index in hits:
            self.endpoint.publish("bumper_hit", {"ring": ring, "index": index})


class SonarDriver(Driver):
    """Sonar rings: sets the firing order (a CONFIG block) and publishes whole rings.

    A module's sonars are numbered across its sonar elements. The firing order sent is the
    configured one restricted to the module's sonars, then the sonars it does not list in index
    order: every sonar is fired. ``sonar_ranges`` goes out each time the frame holding the
    module's last sonar arrives, once every sonar has reported; ``None`` = nothing in range.
    """

    kinds = ("sonar", "firing_sequence")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.ranges: dict[int, list[float | None]] = {}
        self.seen: dict[int, set[int]] = {}

    def firing_order(self, count: int) -> bytes:
        listed = [i for i in dict.fromkeys(self.config.firing_sequence) if 0 <= i < count]
        return bytes(listed + [i for i in range(count) if i not in listed])

    def _count(self, module: Module) -> int:
        assert module.description is not None
        return sum(c for _, c in module.description.numbering(p.ElementKind.SONAR).values())

    async def configure(self, module: Module, index: int, element: p.Element) -> None:
        mid = module.module_id
        if element.kind == p.ElementKind.SONAR:
            self.ranges[mid] = [None] * self._count(module)
            self.seen[mid] = set()
            await self.master.command(
                mid, p.set_param(index, p.Param.PUBLISH_MS, self.config.sonar_period_ms)
            )
        else:
            order = self.firing_order(self._count(module))
            await self.master.send_block(mid, p.BlockType.CONFIG, bytes([index, 0]) + order)
            await self.master.command(mid, p.set_mode(index, 1))  # 1 = fire in that order

    def on_online(self, module: Module) -> None:
        self.seen[module.module_id] = set()

    def on_frame(self, module: Module, element: int, data: bytes) -> None:
        _, first, values = p.parse_sonar(data)
        mid = module.module_id
        numbers = [
            _instance(module, p.ElementKind.SONAR, element, first + k) for k in range(len(values))
        ]
        ring = self.ranges.setdefault(mid, [None] * self._count(module))
        seen = self.seen.setdefault(mid, set())
        for number, value in zip(numbers, values, strict=True):
            ring[number] = value
            seen.add(number)
        if numbers[-1] == len(ring) - 1 and len(seen) == len(ring):
            self.endpoint.publish(
                "sonar_ranges",
                {"ring": self.config.sonar_rings.get(mid, mid), "ranges": list(ring)},
            )


class HeadDriver(Driver):
    """Head and arm servos: ``move_servos`` in, one ``servo_in_position`` per servo out.
    ``DriverConfig.servo_names`` name a module's servos numbered across its servo elements."""

    kinds = ("servo",)

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.modules: dict[int, Module] = {}
        self.positions: dict[str, float] = {}
        self.moving: set[str] = set()

    def start(self) -> None:
        self._unsubscribe.append(self.endpoint.subscribe("move_servos", self._on_move))

    async def configure(self, module: Module, index: int, element: p.Element) -> None:
        self.modules[module.module_id] = module

    def on_lost(self, module: Module, reason: str) -> None:
        self.moving.clear()

    def _servo_index(self, name: str) -> int:
        if name in self.config.servo_names:
            return self.config.servo_names.index(name)
        if name.isdigit() and int(name) < len(self.config.servo_names):
            return int(name)
        raise ValueError(f"unknown servo {name!r}; known: {', '.join(self.config.servo_names)}")

    def _on_move(self, message: Message) -> None:
        servos = message.payload.get("servos")
        try:
            if not isinstance(servos, dict):
                raise ValueError("servos must be an object {name: position}")
            speed = _number(message.payload, "speed", 90.0)
            frames = [(self._servo_index(str(name)), _number(servos, name)) for name in servos]
        except ValueError as exc:
            log.warning("robocan: move_servos refused: %s", exc)
            return
        online = self.master.online()
        for module_id, module in self.modules.items():
            if module_id not in online or module.description is None:
                continue
            numbering = module.description.numbering(p.ElementKind.SERVO)
            for index, position in frames:
                for element, (first, count) in numbering.items():
                    if first <= index < first + count:
                        self.moving.add(self.config.servo_names[index])
                        self.master.send_to(
                            module_id, p.set_servo(element, index - first, position, speed)
                        )

    def on_frame(self, module: Module, element: int, data: bytes) -> None:
        _, index, position, in_position = p.parse_servo(data)
        number = _instance(module, p.ElementKind.SERVO, element, index)
        if number >= len(self.config.servo_names):
            return
        name = self.config.servo_names[number]
        self.positions[name] = position
        if in_position and name in self.moving:
            self.moving.discard(name)
            self.endpoint.publish(ServoInPosition(servo=name, position=position))


class IoDriver(Driver):
    """Capacitive touch inputs (``button_pressed``) and outputs such as eye LEDs (``set_leds``).
    Inputs and outputs of a module are numbered across its touch / LED elements."""

    kinds = ("touch", "led")

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.masks: dict[tuple[int, int], int] = {}  # (module id, touch element) -> mask
        self.led_modules: dict[int, Module] = {}

    def start(self) -> None:
        self._unsubscribe.append(self.endpoint.subscribe("set_leds", self._on_set_leds))

    async def configure(self, module: Module, index: int, element: p.Element) -> None:
        if element.kind == p.ElementKind.LED:
            self.led_modules[module.module_id] = module

    def on_online(self, module: Module) -> None:
        for key in [k for k in self.masks if k[0] == module.module_id]:
            del self.masks[key]

    def _on_set_leds(self, message: Message) -> None:
        leds = message.payload.get("leds")
        if not isinstance(leds, dict):
            log.warning("robocan: set_leds refused: leds must be an object {name: value}")
            return
        online = self.master.online()
        for name, value in leds.items():
            if name not in self.config.led_names:
                log.warning("robocan: set_leds: unknown LED %r", name)
                continue
            level = 255 if value is True else 0 if value is False else value
            if not isinstance(level, int | float):
                log.warning("robocan: set_leds: bad value %r for %s", value, name)
                continue
            index = self.config.led_names.index(name)
            for module_id, module in self.led_modules.items():
                if module_id not in online or module.description is None:
                    continue
                for element, (first, count) in module.description.numbering(
                    p.ElementKind.LED
                ).items():
                    if first <= index < first + count:
                        frame = p.set_output(element, index - first, int(level))
                        self.master.send_to(module_id, frame)

    def on_frame(self, module: Module, element: int, data: bytes) -> None:
        _, mask = p.parse_mask(data)
        key = (module.module_id, element)
        numbers = _new_bits(module, p.ElementKind.TOUCH, element, mask, self.masks.get(key, 0))
        self.masks[key] = mask
        for number in numbers:
            if number < len(self.config.touch_names):
                self.endpoint.publish("button_pressed", {"button": self.config.touch_names[number]})


class BatteryDriver(Driver):
    """Battery level; ``battery_low`` / ``battery_panic`` once per discharge (re-armed when the
    level is back 5 points above the threshold); ``set_charging {on}`` closes the charger
    contact (the dock)."""

    kinds = ("battery",)
    REARM = 0.05

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.modules: set[int] = set()
        self.level: float | None = None
        self.sent: set[str] = set()

    def start(self) -> None:
        self._unsubscribe.append(self.endpoint.subscribe("set_charging", self._on_set_charging))

    async def configure(self, module: Module, index: int, element: p.Element) -> None:
        self.modules.add(module.module_id)

    def _on_set_charging(self, message: Message) -> None:
        on = bool(message.payload.get("on", False))
        for module_id in self.modules & self.master.online():
            self.master.send_to(module_id, bytes([p.Op.SET_CHARGING, 1 if on else 0]))

    def on_frame(self, module: Module, element: int, data: bytes) -> None:
        level, voltage, charging = p.parse_battery(data)
        self.level = level
        self.endpoint.publish(
            "battery_level", {"level": level, "charging": charging, "voltage": voltage}
        )
        if level >= self.config.battery_low + self.REARM:
            self.sent.clear()
        if level <= self.config.battery_panic and "battery_panic" not in self.sent:
            self.sent |= {"battery_panic", "battery_low"}
            self.endpoint.publish(
                "battery_panic", BatteryAlarm(robot=self.config.robot, level=level)
            )
        elif level <= self.config.battery_low and "battery_low" not in self.sent:
            self.sent.add("battery_low")
            self.endpoint.publish("battery_low", BatteryAlarm(robot=self.config.robot, level=level))
