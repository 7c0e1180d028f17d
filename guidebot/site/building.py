"""Building part of the site: Modbus I/O modules, their points, doors, elevators and buttons.

The BuildingInterface (backend/building) and the simulator (building_sim) read these models;
the site validator (guidebot.site.validate) checks that every reference between them resolves.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field, StrictFloat, StrictInt

from guidebot.site.io_rules import PointKind
from guidebot.task_kinds import TaskKind

__all__ = [
    "BuildingModule",
    "Button",
    "ButtonTask",
    "Door",
    "Elevator",
    "ElevatorStop",
    "IOPoint",
    "IORef",
    "PointKind",
]

ID_PATTERN = r"^[A-Za-z0-9_.\-]+$"


class StrictModel(BaseModel):
    """Unknown keys are refused so typos in a site file surface with their place; numbers and
    flags are taken as such only (``true`` is not 1)."""

    model_config = ConfigDict(extra="forbid")


class IOPoint(StrictModel):
    """One input or output of a module; ``node`` places it on the map (a button, a sensor)."""

    name: str = Field(min_length=1, max_length=64, pattern=ID_PATTERN)
    address: StrictInt = Field(ge=0, le=65535)
    kind: PointKind
    node: str | None = None
    description: str = ""


class BuildingModule(StrictModel):
    """A Modbus/TCP I/O module (the paper's Schneider OTB), polled every ``sampling_period_ms``."""

    id: str = Field(min_length=1, max_length=64, pattern=ID_PATTERN)
    host: str = "127.0.0.1"
    port: StrictInt = Field(default=502, ge=0, le=65535)
    unit_id: StrictInt = Field(default=1, ge=0, le=247)
    sampling_period_ms: StrictInt = Field(default=200, ge=10, le=60_000)
    timeout_ms: StrictInt = Field(default=500, ge=10, le=60_000)
    points: list[IOPoint] = Field(default_factory=list)

    def point(self, name: str) -> IOPoint | None:
        return next((p for p in self.points if p.name == name), None)


class IORef(StrictModel):
    """A reference to one point of one module, by names."""

    module: str
    point: str


class Door(StrictModel):
    """An automatic door on the map: a robot passing ``node`` asks the building to open it."""

    id: str = Field(min_length=1, max_length=64, pattern=ID_PATTERN)
    node: str
    open: IORef
    """Output (coil) that opens the door while set."""
    is_open: IORef | None = None
    """Input that reports the door fully open; without it, ``open_time_s`` is waited."""
    open_time_s: StrictFloat = Field(default=2.0, ge=0, le=120)
    max_hold_s: StrictFloat = Field(default=120.0, gt=0, le=3600)
    """A robot holding the door longer than this is dropped (a robot lost mid-door must not
    keep it open for ever); the door closes when no holder is left."""


class ElevatorStop(StrictModel):
    """Where the elevator stops on one floor: its map node and the I/O to call it there."""

    floor: str
    node: str
    call: IORef
    """Output that calls the elevator to this floor."""
    in_position: IORef
    """Input set while the cabin is at this floor with the door open."""


class Elevator(StrictModel):
    """An elevator joining floors; its nodes are linked in the map by ``elevator`` edges."""

    id: str = Field(min_length=1, max_length=64, pattern=ID_PATTERN)
    stops: list[ElevatorStop] = Field(min_length=2)
    travel_time_s: StrictFloat = Field(default=10.0, ge=0, le=600)
    """Used by path cost: riding the elevator costs this much, converted to metres."""


class ButtonTask(StrictModel):
    """The task a button requests (a task_request payload without requester)."""

    kind: TaskKind
    params: dict[str, Any] = Field(default_factory=dict)
    priority: StrictInt = Field(default=5, ge=0, le=100)


class Button(StrictModel):
    """A "press to get a robot" button: its input starts a task request, its LED shows it."""

    id: str = Field(min_length=1, max_length=64, pattern=ID_PATTERN)
    input: IORef
    led: IORef | None = None
    node: str
    task: ButtonTask
