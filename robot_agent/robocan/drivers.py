"""Driver plug-ins: one driver class per kind of component or agent, found through the
``guidebot.robocan_drivers`` entry-point group (name = element kind, e.g. ``pid_velocity``).

The master loads a driver the first time a module declares an element of its kind (the
paper's dynamic loading) and keeps one instance per class. A driver configures its elements,
turns their frames into on-board messages (it is the gateway to an entity) and is told when
its modules come and go.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from importlib.metadata import entry_points
from typing import TYPE_CHECKING, Any, ClassVar

from guidebot.bus import BusEndpoint

if TYPE_CHECKING:
    from robot_agent.robocan.master import Master, Module
    from robot_agent.robocan.protocol import Element

__all__ = ["ENTRY_POINT_GROUP", "Driver", "DriverConfig", "DriverRegistry", "UnknownDriver"]

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "guidebot.robocan_drivers"


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
    """Element kind name -> driver class, from entry points plus explicit registrations."""

    def __init__(self, *, use_entry_points: bool = True) -> None:
        self._classes: dict[str, type[Driver] | str] = {}
        if use_entry_points:
            for ep in entry_points(group=ENTRY_POINT_GROUP):
                self._classes[ep.name] = ep.value

    def register(self, kind: str, cls: type[Driver]) -> None:
        self._classes[kind] = cls

    @property
    def kinds(self) -> list[str]:
        return sorted(self._classes)

    def driver_class(self, kind: str) -> type[Driver]:
        """Import the driver of a kind on first use; raises UnknownDriver."""
        target = self._classes.get(kind)
        if target is None:
            raise UnknownDriver(f"no RoboCAN driver for element kind {kind!r}")
        if isinstance(target, str):
            import importlib

            module_name, _, attribute = target.partition(":")
            cls = getattr(importlib.import_module(module_name), attribute)
            if not (isinstance(cls, type) and issubclass(cls, Driver)):
                raise UnknownDriver(f"{target} is not a RoboCAN Driver")
            self._classes[kind] = cls
            return cls
        return target
