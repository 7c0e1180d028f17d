"""Built-in drivers and the entities they serve on the on-board bus (RoboCAN paper, Figure 5):
base (velocity commands, odometry), bumpers, sonar, head servos, touch inputs and LEDs, battery.

Each class is registered under its element kinds in the ``guidebot.robocan_drivers`` entry
points; message names and fields are those of docs/messages.md.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from guidebot.messages import Message
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
class Wheel:
    side: str
    pid_element: int = 0
    motor_element: int = 0
    last_ticks: int | None = None
    delta_m: float = 0.0
    velocity: float = 0.0
    fresh: bool = False
    online: bool = False


class BaseDriver(Driver):
    """Differential base over two motor controllers (PID velocity agent + motor/encoder).

    Critical: losing a motor controller stops the base and publishes ``base_fault``. While
    the base moves the last command is repeated every ``command_period_s`` (8 Hz); while it is
    stopped no velocity frame is sent (the paper's stopped-state saving).
    """

    kinds = ("pid_velocity", "motor")
    opcodes = frozenset({p.Op.ENCODER})
    critical = True

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.wheels: dict[int, Wheel] = {}
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

    def _wheel(self, module: Module) -> Wheel:
        wheel = self.wheels.get(module.module_id)
        if wheel is None:
            side = self.config.wheel_sides.get(module.module_id)
            if side is None:
                taken = {w.side for w in self.wheels.values()}
                side = "left" if "left" not in taken else "right"
            wheel = self.wheels[module.module_id] = Wheel(side)
        return wheel

    async def configure(self, module: Module, index: int, element: p.Element) -> None:
        wheel = self._wheel(module)
        mid = module.module_id
        if element.kind == p.ElementKind.MOTOR:
            wheel.motor_element = index
            await self.master.command(
                mid, p.set_param(index, p.Param.PUBLISH_MS, self.config.encoder_period_ms)
            )
            await self.master.command(
                mid, p.set_param(index, p.Param.TICKS_PER_M, self.config.ticks_per_m)
            )
        else:
            wheel.pid_element = index
            await self.master.command(mid, p.set_param(index, p.Param.COMMAND_TIMEOUT_MS, 1000))
            await self.master.command(mid, p.set_mode(index, 1))  # 1 = velocity control

    def on_online(self, module: Module) -> None:
        wheel = self._wheel(module)
        wheel.online, wheel.last_ticks, wheel.fresh = True, None, False
        self.faults.discard(module.module_id)

    def on_lost(self, module: Module, reason: str) -> None:
        wheel = self._wheel(module)
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
        """One velocity frame per motor controller, from the current (v, w)."""
        v, w = self.target
        half = w * self.config.wheel_base_m / 2
        for mid, wheel in self.wheels.items():
            if wheel.online:
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

    def on_frame(self, module: Module, data: bytes) -> None:
        _, ticks, velocity = p.parse_encoder(data)
        wheel = self._wheel(module)
        if wheel.last_ticks is not None:
            delta = ((ticks - wheel.last_ticks + 2**31) % 2**32) - 2**31
            wheel.delta_m += delta / self.config.ticks_per_m
        wheel.last_ticks = ticks
        wheel.velocity = velocity
        wheel.fresh = True
        sides = {w.side: w for w in self.wheels.values() if w.online}
        left, right = sides.get("left"), sides.get("right")
        if left is None or right is None or not (left.fresh and right.fresh):
            return
        base = self.config.wheel_base_m
        ds = (left.delta_m + right.delta_m) / 2
        dtheta = (right.delta_m - left.delta_m) / base
        self.x += ds * math.cos(self.theta + dtheta / 2)
        self.y += ds * math.sin(self.theta + dtheta / 2)
        self.theta = math.remainder(self.theta + dtheta, math.tau)
        left.delta_m = right.delta_m = 0.0
        left.fresh = right.fresh = False
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


class BumperDriver(Driver):
    """Bumpers on the sonar rings and motor controllers: a new contact stops the base."""

    kinds = ("bumper",)
    opcodes = frozenset({p.Op.BUMPERS})

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.masks: dict[int, int] = {}

    def on_online(self, module: Module) -> None:
        self.masks[module.module_id] = 0

    def on_frame(self, module: Module, data: bytes) -> None:
        _, mask = p.parse_mask(data)
        pressed = mask & ~self.masks.get(module.module_id, 0)
        self.masks[module.module_id] = mask
        if not pressed:
            return
        for base in self.master.drivers_of(BaseDriver):
            assert isinstance(base, BaseDriver)
            base.stop()
        ring = self.config.bumper_rings.get(module.module_id, module.module_id)
        for index in range(16):
            if pressed & (1 << index):
                self.endpoint.publish("bumper_hit", {"ring": ring, "index": index})


class SonarDriver(Driver):
    """Sonar rings: sets the firing sequence (a block transfer) and publishes whole rings."""

    kinds = ("sonar", "firing_sequence")
    opcodes = frozenset({p.Op.SONAR})

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.ranges: dict[int, list[float | None]] = {}

    async def configure(self, module: Module, index: int, element: p.Element) -> None:
        mid = module.module_id
        if element.kind == p.ElementKind.SONAR:
            self.ranges[mid] = [None] * element.count
            await self.master.command(
                mid, p.set_param(index, p.Param.PUBLISH_MS, self.config.sonar_period_ms)
            )
        else:
            sequence = bytes([index, 0, *self.config.firing_sequence])  # element, param 0
            await self.master.send_block(mid, p.BlockType.CONFIG, sequence)
            await self.master.command(mid, p.set_mode(index, 1))  # 1 = fire in sequence

    def on_frame(self, module: Module, data: bytes) -> None:
        _, first, values = p.parse_sonar(data)
        ring = self.ranges.setdefault(module.module_id, [None] * 8)
        for offset, value in enumerate(values):
            if first + offset < len(ring):
                ring[first + offset] = value
        if first + len(values) >= len(ring) and all(r is not None for r in ring):
            self.endpoint.publish(
                "sonar_ranges",
                {
                    "ring": self.config.sonar_rings.get(module.module_id, module.module_id),
                    "ranges": list(ring),
                },
            )


class HeadDriver(Driver):
    """Head and arm servos: ``move_servos`` in, one ``servo_in_position`` per servo out."""

    kinds = ("servo",)
    opcodes = frozenset({p.Op.SERVO})

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.modules: dict[int, int] = {}  # module id -> servo element
        self.positions: dict[str, float] = {}
        self.moving: set[str] = set()

    def start(self) -> None:
        self._unsubscribe.append(self.endpoint.subscribe("move_servos", self._on_move))

    async def configure(self, module: Module, index: int, element: p.Element) -> None:
        self.modules[module.module_id] = index

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
        for module_id, element in self.modules.items():
            if module_id not in online:
                continue
            for index, position in frames:
                self.moving.add(self.config.servo_names[index])
                self.master.send_to(module_id, p.set_servo(element, index, position, speed))

    def on_frame(self, module: Module, data: bytes) -> None:
        _, index, position, in_position = p.parse_servo(data)
        if index >= len(self.config.servo_names):
            return
        name = self.config.servo_names[index]
        self.positions[name] = position
        if in_position and name in self.moving:
            self.moving.discard(name)
            self.endpoint.publish("servo_in_position", {"servo": name, "position": position})


class IoDriver(Driver):
    """Capacitive touch inputs (``button_pressed``) and outputs such as eye LEDs (``set_leds``)."""

    kinds = ("touch", "led")
    opcodes = frozenset({p.Op.INPUTS})

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.masks: dict[int, int] = {}
        self.led_modules: dict[int, int] = {}

    def start(self) -> None:
        self._unsubscribe.append(self.endpoint.subscribe("set_leds", self._on_set_leds))

    async def configure(self, module: Module, index: int, element: p.Element) -> None:
        if element.kind == p.ElementKind.LED:
            self.led_modules[module.module_id] = index
        else:
            self.masks[module.module_id] = 0

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
            for module_id, element in self.led_modules.items():
                if module_id in online:
                    self.master.send_to(module_id, p.set_output(element, index, int(level)))

    def on_frame(self, module: Module, data: bytes) -> None:
        _, mask = p.parse_mask(data)
        pressed = mask & ~self.masks.get(module.module_id, 0)
        self.masks[module.module_id] = mask
        for index, name in enumerate(self.config.touch_names):
            if pressed & (1 << index):
                self.endpoint.publish("button_pressed", {"button": name})


class BatteryDriver(Driver):
    """Battery level; ``battery_low`` / ``battery_panic`` once per discharge (re-armed when the
    level is back 5 points above the threshold); ``set_charging {on}`` closes the charger
    contact (the dock)."""

    kinds = ("battery",)
    opcodes = frozenset({p.Op.BATTERY})
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

    def on_frame(self, module: Module, data: bytes) -> None:
        level, voltage, charging = p.parse_battery(data)
        self.level = level
        self.endpoint.publish(
            "battery_level", {"level": level, "charging": charging, "voltage": voltage}
        )
        if level >= self.config.battery_low + self.REARM:
            self.sent.clear()
        if level <= self.config.battery_panic and "battery_panic" not in self.sent:
            self.sent |= {"battery_panic", "battery_low"}
            self.endpoint.publish("battery_panic", {"robot": self.config.robot, "level": level})
        elif level <= self.config.battery_low and "battery_low" not in self.sent:
            self.sent.add("battery_low")
            self.endpoint.publish("battery_low", {"robot": self.config.robot, "level": level})
