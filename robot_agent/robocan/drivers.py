"""Driver plug-ins: one driver class per kind of component or agent (name = element kind,
e.g. ``pid_velocity``). The registry starts from the built-in table ``BUILTIN_DRIVERS`` and adds
the ``guidebot.robocan_drivers`` entry points on top (an entry point of a built-in kind replaces
it), as python-can does with its interfaces: a checkout that is not installed still has its
drivers, and a hardware maker's package adds or overrides kinds without touching this one.

The master loads a driver the first time a module declares an element of its kind (the
paper's dynamic loading) and keeps one instance per class. A driver configures its elements,
turns their frames into on-board messages (it is the gateway to an entity) and is told when
its modules come and go.
"""

from __future__ import annotations

import importlib
import logging
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any, ClassVar

from guidebot.bus import BusEndpoint

if TYPE_CHECKING:
    from robot_agent.robocan.master import Master, Module
    from robot_agent.robocan.protocol import Element

__all__ = [
    "BUILTIN_DRIVERS",
    "ENTRY_POINT_GROUP",
    "Driver",
    "DriverConfig",
    "DriverRegistry",
    "UnknownDriver",
]

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "guidebot.robocan_drivers"
_ENTITIES = "robot_agent.robocan.entities"
BUILTIN_DRIVERS: dict[str, str] = {
    "pid_velocity": f"{_ENTITIES}:BaseDriver",
    "motor": f"{_ENTITIES}:BaseDriver",
    "bumper": f"{_ENTITIES}:BumperDriver",
    "sonar": f"{_ENTITIES}:SonarDriver",
    "firing_sequence": f"{_ENTITIES}:SonarDriver",
    "servo": f"{_ENTITIES}:HeadDriver",
    "touch": f"{_ENTITIES}:IoDriver",
    "led": f"{_ENTITIES}:IoDriver",
    "battery": f"{_ENTITIES}:BatteryDriver",
}
"""Element kind -> ``module:Class`` of the drivers that ship with GuideBot (imported on first
use, so that listing kinds imports nothing)."""


class UnknownDriver(LookupError):
    """No driver is registered for an element kind."""


@dataclass
class DriverConfig:
    """Robot geometry and names: what the paper's entity libraries carry."""

    robot: str = "R1"
    wheel_base_m: float = 0.40
    ticks_per_m: int = 20000
    wheel_sides: dict[int, str] = field(default_factory=lambda: {0x02: "left", 0x04: "right"})
    command_period_s: float = 0.125  # velocity commands repeat at 8 Hz while moving
    encoder_period_ms: int = 100  # motor controllers publish at 10 Hz
    sonar_period_ms: int = 500
    sonar_rings: dict[int, int] = field(default_factory=lambda: {0x10: 0, 0x20: 1})
    bumper_rings: dict[int, int] = field(
        default_factory=lambda: {0x10: 0, 0x20: 1, 0x02: 2, 0x04: 3}
    )
    firing_sequence: tuple[int, ...] = (0, 4, 1, 5, 2, 6, 3, 7)
    servo_names: tuple[str, ...] = (
        "head_pan",
        "head_tilt",
        "eyelid_left",
        "eyelid_right",
        "eyebrow_left",
        "eyebrow_right",
        "mouth",
        "arm_left",
        "arm_right",
        "neck_roll",
    )
    touch_names: tuple[str, ...] = (
        "head_top",
        "face_left",
        "face_right",
        "hand_left",
        "hand_right",
        "chest",
    )
    led_names: tuple[str, ...] = ("eye_left", "eye_right", "mouth", "locker")
    battery_low: float = 0.25
    battery_panic: float = 0.10


class Driver:
    """Base class of drivers. Subclasses set ``kinds`` and maybe ``critical``."""

    kinds: ClassVar[tuple[str, ...]] = ()
    critical: ClassVar[bool] = False

    def __init__(self, master: Master, endpoint: BusEndpoint, config: DriverConfig) -> None:
        self.master = master
        self.endpoint = endpoint
        self.config = config
        self._unsubscribe: list[Any] = []

    def start(self) -> None:
        """Subscribe to the on-board messages this driver's entity accepts."""

    def close(self) -> None:
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        self._unsubscribe.clear()

    async def configure(self, module: Module, index: int, element: Element) -> None:
        """Set parameters and working modes of one element before the module is enabled."""

    def on_online(self, module: Module) -> None:
        """The module is configured and enabled."""

    def on_lost(self, module: Module, reason: str) -> None:
        """The module fell silent (or rebooted): forget its state, stop what depends on it."""

    def on_frame(self, module: Module, element: int, data: bytes) -> None:
        """A data frame from an online module for ``element``, one of this driver's kinds (the
        master checked that). Raise ``ProtocolError`` for content that cannot be (a servo
        index beyond the element's count): the master counts it as a bad frame."""


class DriverRegistry:
    """Element kind name -> driver class: the built-in table, then entry points on top, then
    explicit registrations. ``source(kind)`` says where a kind's driver came from."""

    def __init__(self, *, use_entry_points: bool = True) -> None:
        self._classes: dict[str, type[Driver] | str] = dict(BUILTIN_DRIVERS)
        self._sources: dict[str, str] = dict.fromkeys(BUILTIN_DRIVERS, "built-in")
        if use_entry_points:
            for ep in entry_points(group=ENTRY_POINT_GROUP):
                if BUILTIN_DRIVERS.get(ep.name) == ep.value:
                    continue  # an older install of GuideBot itself declared its own drivers
                self._classes[ep.name] = ep.value
                dist = ep.dist.name if ep.dist is not None else "?"
                self._sources[ep.name] = f"entry point {ep.name} = {ep.value} ({dist})"

    def register(self, kind: str, cls: type[Driver]) -> None:
        self._classes[kind] = cls
        self._sources[kind] = "registered"

    @property
    def kinds(self) -> list[str]:
        return sorted(self._classes)

    def source(self, kind: str) -> str:
        """``built-in``, ``registered`` or the entry point (and its distribution)."""
        return self._sources.get(kind, "unknown")

    def driver_class(self, kind: str) -> type[Driver]:
        """Import the driver of a kind on first use; raises UnknownDriver, also when the
        target cannot be imported or is not a Driver (the other kinds are not affected)."""
        target = self._classes.get(kind)
        if target is None:
            raise UnknownDriver(f"no RoboCAN driver for element kind {kind!r}")
        if not isinstance(target, str):
            return target
        module_name, _, attribute = target.partition(":")
        where = f"RoboCAN driver for {kind!r} ({self.source(kind)})"
        try:
            cls = getattr(importlib.import_module(module_name), attribute)
        except Exception as exc:  # a broken plug-in must not take the master down
            raise UnknownDriver(
                f"{where}: cannot load {target}: {type(exc).__name__}: {exc}"
            ) from exc
        if not (isinstance(cls, type) and issubclass(cls, Driver)):
            raise UnknownDriver(f"{where}: {target} is not a subclass of robocan Driver")
        self._classes[kind] = cls
        return cls
