"""Payload models of the building messages (registered by type name).

The BuildingInterface answers commands (open_door, close_door, call_elevator, set_output) with a
confirmation or ``command_failed``, correlated to the request, and broadcasts input changes and
module health. Field names are the contract in docs/messages.md.
"""

from __future__ import annotations

from enum import StrEnum
from typing import Annotated

from pydantic import Field

from guidebot.messages import PayloadModel, WireEnum, register_payload

__all__ = [
    "BuildingInputChanged",
    "BuildingModuleHealth",
    "CabinState",
    "CallElevator",
    "CloseDoor",
    "CommandFailed",
    "DoorClosed",
    "DoorOpened",
    "ElevatorInPosition",
    "ElevatorState",
    "OpenDoor",
    "ReleaseDoor",
    "SetOutput",
]


@register_payload("open_door")
class OpenDoor(PayloadModel):
    door: str = Field(min_length=1, max_length=64)


@register_payload("close_door")
class CloseDoor(PayloadModel):
    door: str = Field(min_length=1, max_length=64)


@register_payload("release_door")
class ReleaseDoor(PayloadModel):
    """The requester no longer needs the door it opened (it has passed it)."""

    door: str = Field(min_length=1, max_length=64)


@register_payload("door_opened")
class DoorOpened(PayloadModel):
    door: str


@register_payload("door_closed")
class DoorClosed(PayloadModel):
    door: str
    sensed: bool = True
    """False: the door's sensor cannot be read (its module is offline or faulty). The door is
    not passable, but may still stand open: nobody can clear its coil meanwhile."""


@register_payload("call_elevator")
class CallElevator(PayloadModel):
    elevator: str = Field(min_length=1, max_length=64)
    floor: str = Field(min_length=1, max_length=64)


@register_payload("elevator_in_position")
class ElevatorInPosition(PayloadModel):
    elevator: str
    floor: str
    door_open: bool = True


class CabinState(StrEnum):
    """What an elevator car is doing, as far as the building's inputs tell."""

    unknown = "unknown"  # not seen at a floor yet (no floor register, never stood open)
    idle = "idle"  # at its floor, door closed
    door_open = "door_open"
    moving = "moving"  # called to another floor than the one it was last seen at


@register_payload("elevator_state")
class ElevatorState(PayloadModel):
    """Where a car is, on every change (backend.building.elevators): for the staff console."""

    elevator: str
    floor: str | None
    """Its floor, or the last one it was seen at while moving; None before any."""
    door_open: bool
    state: Annotated[CabinState, WireEnum]
    calls: list[str] = Field(default_factory=list)
    """Floors it is called to (their call coils are set)."""


@register_payload("set_output")
class SetOutput(PayloadModel):
    """Write one output: a coil (bool) or a holding register (0..65535)."""

    module: str = Field(min_length=1, max_length=64)
    point: str = Field(min_length=1, max_length=64)
    value: int | bool


@register_payload("command_failed")
class CommandFailed(PayloadModel):
    """The reason says what failed and why, in words an operator can act on."""

    command: str
    reason: str
    target: str | None = None
    """What it was for: the door, the elevator, ``module/point`` (None: unknown, bad payload)."""
    refused: bool = False
    """A rule refused it (the fire alarm holds the device's zone): the device did not fail, so
    no alert and no trouble closure. A robot outside the alarm's zone asks again every few
    seconds while the alarm lasts: each refusal raised an alert among the alarm's own."""


@register_payload("building_input_changed")
class BuildingInputChanged(PayloadModel):
    module: str
    point: str
    name: str
    value: int | bool
    node: str | None = None
    floor: str | None = None
    sampled_at: float | None = None
    """Wall time (time.time()) the server received the first sample showing the new value:
    the anti-spurious filter runs from there (docs/reaction.md)."""


@register_payload("building_module_health")
class BuildingModuleHealth(PayloadModel):
    module: str
    online: bool
    rtt_ms: float | None = None
    errors: int = 0
    last_error: str | None = None
