"""Payload models of the robot messages (registered by type name).

These are what a robot agent reports to the server: its state at a steady rate, battery
thresholds crossed, and faults. On-board-only messages (navigate_to, say, ...) are not
registered here: the on-board bus does not require registration.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated, Literal

from pydantic import Field

from guidebot.messages import PayloadModel, WireEnum, register_payload

__all__ = [
    "ENDED_REPORTED",
    "BatteryAlarm",
    "CanModuleState",
    "EndedTask",
    "NodeReached",
    "RobocanBus",
    "RobocanCounters",
    "RobocanModule",
    "RobocanStatus",
    "RobotFault",
    "RobotMode",
    "RobotState",
]

ENDED_REPORTED = 3
"""Ended tasks a robot_state carries (the newest first)."""


class RobotMode(StrEnum):
    IDLE = "idle"
    BUSY = "busy"
    CHARGING = "charging"
    FAULT = "fault"
    OFFLINE = "offline"


class EndedTask(PayloadModel):
    """A task the robot ended, as its task_ended said it."""

    task_id: str = Field(min_length=1, max_length=64)
    outcome: Literal["done", "failed", "cancelled"]
    reason: str = Field(default="", max_length=500)
    trouble: bool = False
    """As task_ended's ``trouble``."""


@register_payload("robot_state")
class RobotState(PayloadModel):
    """The robot's state, published at a steady rate and at once after a reconnect."""

    robot: str
    x: float = 0.0
    y: float = 0.0
    theta: float = 0.0
    node: str | None = None
    floor: str | None = None
    battery: float = Field(default=1.0, ge=0.0, le=1.0)
    mode: Annotated[RobotMode, WireEnum] = RobotMode.IDLE
    navigation: str | None = None
    """The navigator's state (moving, waiting_door, door_blocked, riding, ...)."""
    task_id: str | None = None
    speed: float = 0.0
    nets: list[str] = Field(default_factory=list)
    modules: dict[str, str] = Field(default_factory=dict)
    poi: str | None = None
    """The point of interest the current task last showed (a tour's current step)."""
    areas: list[str] = Field(default_factory=list, max_length=64)
    """Restricted areas the robot holds or was granted: after a server restart the Traffic
    Manager takes them from here (its lock table starts empty)."""
    ended: list[EndedTask] = Field(default_factory=list, max_length=ENDED_REPORTED)
    """The last tasks the robot ended, newest first: a server that restarted with one of them
    still assigned ends it from here even if its task_ended never arrived (dropped from a
    full queue during a long freeze), rather than giving it out again."""
    boot_id: str | None = Field(default=None, max_length=64)
    """A random id drawn once per agent process: a new one for a known robot tells the server
    the old process is gone (its holds are stale: docs/server.md, "Lock policy")."""
    seq: int = 0


@register_payload("battery_low")
@register_payload("battery_panic")
class BatteryAlarm(PayloadModel):
    """battery_low: finish the task then charge; battery_panic: cancel it and charge now."""

    robot: str
    level: float = Field(ge=0.0, le=1.0)


@register_payload("robot_fault")
class RobotFault(PayloadModel):
    robot: str
    kind: str = Field(min_length=1, max_length=64)
    detail: str = ""


@register_payload("node_reached")
class NodeReached(PayloadModel):
    """The robot has reached a node of its path: what the fleet's invariants are checked on."""

    robot: str
    node: str
    floor: str | None = None
    at: float | None = None
    """When the robot reached it (Unix seconds, the robot's clock): a report held back while
    the link was down arrives late, and the invariants are checked at this time."""


class CanModuleState(StrEnum):
    """A RoboCAN module's state in its master's table (docs/robocan.md, section 8)."""

    querying = "querying"
    configuring = "configuring"
    online = "online"
    disabled = "disabled"
    lost = "lost"
    failed = "failed"


class RobocanCounters(PayloadModel):
    """What the master of one bus counted (docs/robocan.md, section 7 says when each counts)."""

    frames_rx: int = Field(ge=0)
    frames_tx: int = Field(ge=0)
    unknown_id: int = Field(ge=0)
    bad_frame: int = Field(ge=0)
    overflow: int = Field(ge=0)
    block_errors: int = Field(ge=0)
    send_errors: int = Field(ge=0)
    driver_errors: int = Field(ge=0)
    record_errors: int = Field(ge=0)
    stalls: int = Field(ge=0)
    not_online: int = Field(ge=0)
    modules_lost: int = Field(ge=0)
    modules_requeried: int = Field(ge=0)


class RobocanModule(PayloadModel):
    """One row of a master's module table."""

    module_id: int = Field(ge=0, le=0x7F)
    name: str
    kind: str | None
    """motor_controller, sonar_ring, head_io, battery_monitor, other or kind_N; None before the
    module described itself."""
    firmware: str | None
    state: Annotated[CanModuleState, WireEnum]
    critical: bool
    elements: list[str] = Field(default_factory=list)
    frames_rx: int = Field(ge=0)
    frames_tx: int = Field(ge=0)
    errors: int = Field(ge=0)
    faults: int = Field(ge=0)
    lost: int = Field(ge=0)
    requeried: int = Field(ge=0)


class RobocanBus(PayloadModel):
    bus: str
    counters: RobocanCounters
    modules: list[RobocanModule] = Field(default_factory=list)


@register_payload("robocan_status")
class RobocanStatus(PayloadModel):
    """A robot's CAN buses, their counters and module tables: on board every second, to the
    server at most every few seconds and at once when a module changes state (the link)."""

    robot: str
    buses: list[RobocanBus] = Field(default_factory=list)

    def module_states(self) -> tuple[tuple[str, int, str], ...]:
        """What a person must see at once when it changes: every module's state."""
        return tuple(
            (bus.bus, m.module_id, m.state.value) for bus in self.buses for m in bus.modules
        )
