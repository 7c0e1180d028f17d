"""Simulated building devices: automatic doors, elevators and buttons.

Devices act on the module stores the way wired hardware would: a door reads its open coil and
drives its "fully open" sensor; an elevator reads its call coils and drives its in-position
inputs. Everything runs on loop timers (no tasks); durations are divided by the time scale.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from enum import StrEnum

from guidebot.site.building import Door, Elevator, IORef

__all__ = [
    "CabinState",
    "DoorSim",
    "DoorState",
    "ElevatorSim",
    "IllegalTransition",
    "PointWriter",
]

# (module, point name, value): how a device changes an input or output of a module.
PointWriter = Callable[[IORef, int], None]


class IllegalTransition(RuntimeError):
    """A device was asked to move to a state its table does not allow."""


class DoorState(StrEnum):
    closed = "closed"
    opening = "opening"
    open = "open"
    closing = "closing"


DOOR_TRANSITIONS: dict[DoorState, frozenset[DoorState]] = {
    DoorState.closed: frozenset({DoorState.opening}),
    DoorState.opening: frozenset({DoorState.open, DoorState.closing}),
    DoorState.open: frozenset({DoorState.closing}),
    DoorState.closing: frozenset({DoorState.closed, DoorState.opening}),
}


class _Timed:
    """One pending timer per device: a new step cancels the old one."""

    def __init__(self) -> None:
        self._timer: asyncio.TimerHandle | None = None

    def _after(self, seconds: float, step: Callable[[], None]) -> None:
        self.cancel()
        self._timer = asyncio.get_running_loop().call_later(max(0.0, seconds), step)

    def cancel(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None


class DoorSim(_Timed):
    """An automatic door: opens ``open_time_s`` after its coil is set and stays open while the
    coil stays set (the site's contract: "opens the door while set"); clearing the coil closes
    it (sensor off at once). ``hold_s`` (None: never) models a building whose door closes by
    itself after that long, clearing its coil; ``jammed`` doors never open."""

    def __init__(
        self, door: Door, write: PointWriter, *, time_scale: float, hold_s: float | None = None
    ) -> None:
        super().__init__()
        self.door = door
        self.write = write
        self.scale = time_scale
        self.hold_s = hold_s
        self.state = DoorState.closed
        self.openings = 0
        self.jammed = False

    def _go(self, new: DoorState) -> None:
        if new not in DOOR_TRANSITIONS[self.state]:
            raise IllegalTransition(
                f"door {self.door.id}: {self.state.value} -> {new.value} not allowed;"
                f" expected one of {sorted(s.value for s in DOOR_TRANSITIONS[self.state])}"
            )
        self.state = new

    def _sensor(self, value: int) -> None:
        if self.door.is_open is not None:
            self.write(self.door.is_open, value)

    def on_open_coil(self, value: int) -> None:
        if value and self.jammed:
            return
        if value and self.state in (DoorState.closed, DoorState.closing):
            self._go(DoorState.opening)
            self._after(self.door.open_time_s / self.scale, self._opened)
        elif not value and self.state in (DoorState.opening, DoorState.open):
            self._start_closing()

    def _opened(self) -> None:
        self._go(DoorState.open)
        self.openings += 1
        self._sensor(1)
        if self.hold_s is not None:
            self._after(self.hold_s / self.scale, self._hold_over)

    def _hold_over(self) -> None:
        self.write(self.door.open, 0)
        self._start_closing()

    def _start_closing(self) -> None:
        self._go(DoorState.closing)
        self._sensor(0)
        self._after(self.door.open_time_s / self.scale, self._closed)

    def _closed(self) -> None:
        self._go(DoorState.closed)


class CabinState(StrEnum):
    idle = "idle"  # at a floor, door closed
    moving = "moving"
    door_open = "door_open"


CABIN_TRANSITIONS: dict[CabinState, frozenset[CabinState]] = {
    CabinState.idle: frozenset({CabinState.moving, CabinState.door_open}),
    CabinState.moving: frozenset({CabinState.moving, CabinState.door_open}),
    CabinState.door_open: frozenset({CabinState.idle}),
}


class ElevatorSim(_Timed):
    """An elevator: call coils per floor, travel floor by floor, in-position input per floor
    while the cabin is there with its door open. Optional input registers ``<id>_floor`` and
    ``<id>_door`` on the first stop's module report the floor index and door state. A ``stuck``
    cabin (a fault) keeps its calls but never leaves its floor until freed: it never arrives."""

    def __init__(
        self,
        elevator: Elevator,
        write: PointWriter,
        *,
        time_scale: float,
        hold_s: float,
        registers: tuple[IORef | None, IORef | None] = (None, None),
    ) -> None:
        super().__init__()
        self.elevator = elevator
        self.write = write
        self.scale = time_scale
        self.hold_s = hold_s
        self.floor_s = elevator.travel_time_s / max(1, len(elevator.stops) - 1)
        self.state = CabinState.idle
        self.index = 0
        self.direction = 0
        self.pending: set[int] = set()
        self.floor_register, self.door_register = registers
        self.arrivals = 0
        self.stuck = False

    def set_stuck(self, stuck: bool) -> None:
        """Stuck: calls are kept, the cabin does not move; freed: it serves them."""
        self.stuck = stuck
        if not stuck and self.state == CabinState.idle:
            self._next()

    @property
    def floor(self) -> str:
        return self.elevator.stops[self.index].floor

    def _go(self, new: CabinState) -> None:
        if new not in CABIN_TRANSITIONS[self.state]:
            raise IllegalTransition(
                f"elevator {self.elevator.id}: {self.state.value} -> {new.value} not allowed;"
                f" expected one of {sorted(s.value for s in CABIN_TRANSITIONS[self.state])}"
            )
        self.state = new

    def _report(self, door_open: bool) -> None:
        if self.floor_register is not None:
            self.write(self.floor_register, self.index)
        if self.door_register is not None:
            self.write(self.door_register, int(door_open))

    def on_call(self, index: int, value: int) -> None:
        if not value:
            self.pending.discard(index)
            return
        if index == self.index and self.state == CabinState.door_open and not self.stuck:
            self.write(self.elevator.stops[index].call, 0)
            self._after(self.hold_s / self.scale, self._door_closes)
            return
        self.pending.add(index)
        if self.state == CabinState.idle:
            self._next()

    def _next(self) -> None:
        if not self.pending or self.stuck:
            return
        target = min(self.pending, key=lambda i: abs(i - self.index))
        if target == self.index:
            self._arrive()
            return
        self.direction = 1 if target > self.index else -1
        self._go(CabinState.moving)
        self._report(False)
        self._after(self.floor_s / self.scale, self._step)

    def _step(self) -> None:
        """One floor further in the travel direction; a cabin never turns back mid-floor."""
        self.index += self.direction
        self._report(False)
        ahead = [i for i in self.pending if (i - self.index) * self.direction > 0]
        if self.index in self.pending or not self.pending:
            self._arrive()
            return
        if not ahead:  # the only calls left are behind: turn round
            self.direction = -self.direction
        self._go(CabinState.moving)
        self._after(self.floor_s / self.scale, self._step)

    def _arrive(self) -> None:
        self.pending.discard(self.index)
        stop = self.elevator.stops[self.index]
        self.write(stop.call, 0)
        self._go(CabinState.door_open)
        self.arrivals += 1
        self.write(stop.in_position, 1)
        self._report(True)
        self._after(self.hold_s / self.scale, self._door_closes)

    def _door_closes(self) -> None:
        self.write(self.elevator.stops[self.index].in_position, 0)
        self._go(CabinState.idle)
        self._report(False)
        self._next()
