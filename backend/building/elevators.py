"""Where each elevator car is, from what the building's modules say: the in-position input of
each stop (on while the car stands there with its door open), the call coils, and the optional
``<elevator>_floor`` / ``<elevator>_door`` input registers (floor index, door 0/1) on the first
stop's module. The console shows this (``elevator_state``); nothing steers by it.

Without the registers a car's floor is known once it has stood at one with its door open, and
stays that floor until it is seen at another: it only leaves a floor when called elsewhere
(then it is "moving").
"""

from __future__ import annotations

from dataclasses import dataclass, field

from guidebot.payloads.building import CabinState, ElevatorState
from guidebot.site.building import Elevator
from guidebot.site.building_config import BuildingConfig

__all__ = ["ElevatorWatch"]

Key = tuple[str, str]


@dataclass
class _Car:
    elevator: Elevator
    here: dict[str, bool] = field(default_factory=dict)
    """Floor -> its in-position input."""
    called: dict[str, bool] = field(default_factory=dict)
    """Floor -> its call coil."""
    floor_index: int | None = None
    door: int | None = None
    last_floor: str | None = None

    def state(self) -> ElevatorState:
        floors = [s.floor for s in self.elevator.stops]
        at = next((f for f in floors if self.here.get(f)), None)
        if at is None and self.floor_index is not None and 0 <= self.floor_index < len(floors):
            at = floors[self.floor_index]
        if at is not None:
            self.last_floor = at
        floor = at or self.last_floor
        door_open = any(self.here.values()) or self.door == 1
        calls = [f for f in floors if self.called.get(f)]
        if door_open:
            state = CabinState.door_open
        elif any(f != floor for f in calls):
            state = CabinState.moving
        elif floor is None:
            state = CabinState.unknown
        else:
            state = CabinState.idle
        return ElevatorState(
            elevator=self.elevator.id, floor=floor, door_open=door_open, state=state, calls=calls
        )


class ElevatorWatch:
    """Follows every car; ``observe`` says which car's state a new point value changed."""

    def __init__(self, config: BuildingConfig) -> None:
        self.cars = {e.id: _Car(e) for e in config.elevators}
        self._points: dict[Key, tuple[str, str, str]] = {}  # key -> (elevator, what, floor)
        for e in config.elevators:
            for stop in e.stops:
                self._points[(stop.in_position.module, stop.in_position.point)] = (
                    e.id,
                    "here",
                    stop.floor,
                )
                self._points[(stop.call.module, stop.call.point)] = (e.id, "call", stop.floor)
            first = e.stops[0].call.module
            self._points[(first, f"{e.id}_floor")] = (e.id, "floor", "")
            self._points[(first, f"{e.id}_door")] = (e.id, "door", "")
        self._last: dict[str, ElevatorState] = {}

    def observe(self, key: Key, value: int) -> ElevatorState | None:
        """The car's new state if this value changed it, else None."""
        point = self._points.get(key)
        if point is None:
            return None
        elevator, what, floor = point
        car = self.cars[elevator]
        if what == "here":
            car.here[floor] = bool(value)
        elif what == "call":
            car.called[floor] = bool(value)
        elif what == "floor":
            car.floor_index = int(value)
        else:
            car.door = int(value)
        state = car.state()
        if self._last.get(elevator) == state:
            return None
        self._last[elevator] = state
        return state

    def states(self) -> list[ElevatorState]:
        return [car.state() for car in self.cars.values()]
