"""BuildingInterface: the central server's link to the building's Modbus I/O modules.

Generic (the paper's point): everything venue-specific comes from the site's building section.
It polls every module (backend.building.poller), filters inputs (backend.building.filter),
publishes ``building_input_changed`` (with the point's map node and floor) and
``building_module_health`` on the hub, and executes ``open_door``, ``release_door``,
``close_door``, ``call_elevator`` and ``set_output``, confirming each or answering
``command_failed``. Door and cabin states are broadcast on every change of their sensors
(``door_opened``/``door_closed``, ``elevator_in_position`` with ``door_open``): the fleet and
the invariant checker (guidebot.invariants) follow the building, not the commands.

A button press is the paper's T1-T4: this module publishes the input change with its map
position (T2-T3); the Task Manager's ButtonWatcher (backend.tasks.buttons) turns it into the
task bound to the button and drives the button's LED through ``set_output`` (T4).
"""

from __future__ import annotations

import asyncio
import functools
import logging
import time
from collections.abc import Awaitable, Callable, Collection, Mapping
from typing import Any

from pydantic import ValidationError

from backend.building._modbus import ModbusIOError
from backend.building.doors import DoorKeeper, DoorRefused, DoorReleased, DoorShut
from backend.building.elevators import ElevatorWatch
from backend.building.filter import InputFilter
from backend.building.poller import HealthState, ModuleHealth, ModulePoller, Sample
from backend.health import ComponentState
from backend.traffic.restarts import BootIds
from guidebot.bus import BusEndpoint
from guidebot.messages import Message
from guidebot.payloads.building import (
    CallElevator,
    CloseDoor,
    CommandFailed,
    DoorClosed,
    DoorOpened,
    ElevatorInPosition,
    OpenDoor,
    ReleaseDoor,
    SetOutput,
)
from guidebot.payloads.robot import RobotState
from guidebot.service import Service, cancel_and_wait
from guidebot.site.building import Door, Elevator, ElevatorStop, IOPoint, IORef, PointKind
from guidebot.site.building_config import BuildingConfig
from guidebot.site.io_rules import Role, allowed

__all__ = ["BuildingInterface", "CommandError"]

log = logging.getLogger(__name__)

MAX_COMMANDS = 64  # commands in progress; beyond this a command fails at once with "busy"


ALARM_POLL_MS = 50
"""A fire alarm's input is also read on its own at this period (one small read on a second
connection to its module): the alarm need not wait for the module's whole poll (200 ms on the
demo). docs/emergency.md, "Measured"."""
ALARM_FILTER_MS = 50.0
"""The anti-spurious filter of a fire alarm's input: a panel's relay holds until the alarm is
reset, so the 200 ms a person's button press needs (the paper's rule) only delays the alarm;
50 ms still ignores a contact's bounce and a one-sample glitch."""


class CommandError(Exception):
    """A building command that cannot be done; the text is the command_failed reason."""


class CommandRefused(CommandError):
    """A rule refused the command (the fire alarm holds its device's zone): ``refused``."""


class BuildingInterface(Service):
    """Polls the modules of one site and serves building commands on the hub."""

    def __init__(
        self,
        endpoint: BusEndpoint,
        config: BuildingConfig,
        *,
        filter_ms: float = 200.0,
        command_margin_s: float = 5.0,
        health_interval_s: float = 5.0,
        floor_of_node: Mapping[str, str] | None = None,
        alarm_inputs: Mapping[tuple[str, str], int] | None = None,
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self.config = config.check()
        self.filter_s = filter_ms / 1000
        self._alarm_value = dict(alarm_inputs or {})
        """(module, point) -> the value that means alarm, for the fire alarm's inputs."""
        self._filter_of = {key: ALARM_FILTER_MS / 1000 for key in self._alarm_value}
        """(module, point) -> its own filter (the fire alarm's inputs)."""
        self.command_margin_s = command_margin_s
        count = max(1, len(config.modules))
        self.pollers = {
            m.id: ModulePoller(
                m, self._on_sample, self._on_health, health_interval_s, phase=index / count
            )
            for index, m in enumerate(config.modules)
        }
        self.alarm_pollers: dict[str, ModulePoller] = {}
        """Module -> a poller of its fire alarm inputs alone, every ALARM_POLL_MS."""
        self._alarm_health: dict[str, HealthState] = {}
        for m in config.modules:
            points = [p for p in m.points if (m.id, p.name) in self._filter_of]
            if points:
                fast = m.model_copy(update={"points": points, "sampling_period_ms": ALARM_POLL_MS})
                self.alarm_pollers[m.id] = ModulePoller(
                    fast, self._on_sample, self._on_alarm_health, health_interval_s
                )
        # (module, kind, address) -> point, for decoding samples.
        self._points: dict[str, dict[tuple[PointKind, int], IOPoint]] = {
            m.id: {(p.kind, p.address): p for p in m.points} for m in config.modules
        }
        self.values: dict[tuple[str, str], int] = {}
        self._filters: dict[tuple[str, str], InputFilter] = {}
        self._first_seen: dict[tuple[str, str], float] = {}  # wall time, docs/reaction.md
        self._waiters: dict[tuple[str, str], list[tuple[int, asyncio.Future[None]]]] = {}
        self._floors: dict[tuple[str, str], str] = {}
        if floor_of_node:
            for module in config.modules:
                for point in module.points:
                    if point.node is not None and point.node in floor_of_node:
                        self._floors[(module.id, point.name)] = floor_of_node[point.node]
        for elevator in config.elevators:
            for stop in elevator.stops:
                self._floors[(stop.in_position.module, stop.in_position.point)] = stop.floor
        self.doors = {d.id: DoorKeeper(d, self._publish_door) for d in config.doors}
        # (module, point) -> door keeper, for the doors' sensors and coils.
        self._door_sensors = {
            (d.is_open.module, d.is_open.point): self.doors[d.id]
            for d in config.doors
            if d.is_open is not None
        }
        self._door_coils = {(d.open.module, d.open.point): self.doors[d.id] for d in config.doors}
        """Doors whose open coil could not be cleared (module offline): cleared when it is back,
        else the building keeps the door open for ever (found by the soak)."""
        # (module, point) -> (elevator, floor) of each in_position input; its last state.
        self._stops = {
            (s.in_position.module, s.in_position.point): (e.id, s.floor)
            for e in config.elevators
            for s in e.stops
        }
        self._cabin: dict[tuple[str, str], bool] = {}
        self.elevators = ElevatorWatch(config)
        self.boots = BootIds()
        """Each robot's agent process: a new one lets go of the doors the old one held."""
        """Where each car is (``elevator_state``), for the console."""
        self._moved: dict[str, float] = {}
        """Elevator -> monotonic time its cabin last arrived at or left a stop (its progress)."""
        self._commands: set[asyncio.Task[None]] = set()
        self.events = 0
        self.gate: Callable[[str], str | None] | None = None
        """Asked with a device's node before a door opens or a cabin is called: a reason to
        refuse (the fire alarm holds that node, backend.emergency), or None."""

    # -- life cycle ----------------------------------------------------------------------------

    async def on_start(self) -> None:
        # Given back in reverse: subscriptions, commands running, pollers, doors held.
        self.on_cleanup(self._release_doors)
        for poller in [*self.pollers.values(), *self.alarm_pollers.values()]:
            poller.start()
            self.on_cleanup(poller.stop)
        self.on_cleanup(self._cancel_commands)
        handlers: dict[str, Callable[[Message], Awaitable[dict[str, Any]]]] = {
            "open_door": self._open_door,
            "release_door": self._release_door,
            "close_door": self._close_door,
            "call_elevator": self._call_elevator,
            "set_output": self._set_output,
        }
        for type_name, handler in handlers.items():
            self.subscribe(
                self.endpoint, type_name, functools.partial(self._spawn, handler=handler)
            )
        self.on(self.endpoint, RobotState, self._on_robot_state)

    async def _cancel_commands(self) -> None:
        for task in list(self._commands):
            await cancel_and_wait(task)

    def _release_doors(self) -> None:
        for keeper in self.doors.values():
            keeper.release_all()

    def component_state(self) -> tuple[ComponentState, str]:
        """For /api/health: degraded while any module does not answer normally."""
        bad = [
            f"{p.module.id} {p.health.state.value}"
            for p in self.pollers.values()
            if p.health.state != HealthState.online
        ]
        count = len(self.pollers)
        if bad:
            return ComponentState.degraded, f"{count - len(bad)}/{count} modules online; " + (
                ", ".join(bad)
            )
        return ComponentState.ok, f"{count}/{count} modules online"

    def health(self) -> list[dict[str, object]]:
        """Every module's health, for the admin GUI and the REST API."""
        return [
            p.health.payload().model_dump() | {"state": p.health.state.value}
            for p in self.pollers.values()
        ]

    # -- inputs --------------------------------------------------------------------------------

    def _on_alarm_health(self, health: ModuleHealth) -> None:
        """The module's own poller reports its health; this one's changes are only logged
        (the module's poll still reads the alarm inputs)."""
        if self._alarm_health.get(health.module) is health.state:
            return
        self._alarm_health[health.module] = health.state
        if not health.online:
            log.warning("module %s, alarm inputs' poll: %s", health.module, health.last_error)

    def _on_health(self, health: ModuleHealth) -> None:
        self.endpoint.publish(health.payload())
        if health.state == HealthState.online:
            for keeper in self.doors.values():
                if (
                    keeper.coil_left_set
                    and keeper.door.open.module == health.module
                    and not keeper.holders
                ):
                    task = asyncio.get_running_loop().create_task(self._clear_left_coil(keeper))
                    self._commands.add(task)
                    task.add_done_callback(self._commands.discard)
        else:
            # Unknown is closed: a door whose sensor cannot be read is not passable.
            now = time.monotonic()
            for (module, _), keeper in self._door_sensors.items():
                if module == health.module:
                    keeper.lost(now)

    def _on_sample(self, module_id: str, sample: Sample, t: float) -> None:
        points = self._points[module_id]
        for kind, (first, values) in sample.items():
            for offset, raw in enumerate(values):
                point = points.get((kind, first + offset))
                if point is not None:
                    self._observe(module_id, point, raw, t)
                    self._devices(module_id, point, t)

    def _devices(self, module_id: str, point: IOPoint, t: float) -> None:
        """Door and cabin states from their (filtered) inputs, on every sample."""
        key = (module_id, point.name)
        value = self.values[key]
        keeper = self._door_sensors.get(key)
        if keeper is not None:
            keeper.sensor(value, t)
        keeper = self._door_coils.get(key)
        if keeper is not None:
            keeper.coil(value, t)
        car = self.elevators.observe(key, value)
        if car is not None:
            self.endpoint.publish(car)
        stop = self._stops.get(key)
        if stop is not None and self._cabin.get(key) != bool(value):
            self._cabin[key] = bool(value)
            elevator, floor = stop
            self._moved[elevator] = time.monotonic()
            self.endpoint.publish(
                ElevatorInPosition(elevator=elevator, floor=floor, door_open=bool(value)),
            )

    def _publish_door(self, door: str, is_open: bool, sensed: bool) -> None:
        self.endpoint.publish(
            DoorOpened(door=door) if is_open else DoorClosed(door=door, sensed=sensed)
        )

    def _observe(self, module_id: str, point: IOPoint, raw: int, t: float) -> None:
        key = (module_id, point.name)
        if key not in self.values:  # first sample: the baseline, not an event
            self.values[key] = raw
            if point.kind == PointKind.discrete_input:
                self._filters[key] = InputFilter(
                    self._filter_of.get(key, self.filter_s),
                    raw,
                    active=self._alarm_value.get(key, 1),
                )
            self._wake(key, raw)
            return
        if point.kind == PointKind.discrete_input:
            input_filter = self._filters[key]
            new = input_filter.update(raw, t)
            if new is None:
                if input_filter.pending:
                    self._first_seen.setdefault(key, time.time())
                else:
                    self._first_seen.pop(key, None)
                return
        elif raw == self.values[key]:
            return
        else:
            new = raw
        self.values[key] = new
        self.events += 1
        value: int | bool = (
            bool(new) if point.kind in (PointKind.discrete_input, PointKind.coil) else new
        )
        self.endpoint.publish(
            "building_input_changed",
            {
                "module": module_id,
                "point": point.name,
                "name": point.description or point.name,
                "value": value,
                "node": point.node,
                "floor": self._floors.get(key),
                "sampled_at": self._first_seen.pop(key, None) or time.time(),
            },
        )
        self._wake(key, new)

    def _wake(self, key: tuple[str, str], value: int) -> None:
        waiters = self._waiters.get(key)
        if not waiters:
            return
        for wanted, future in list(waiters):
            if wanted == value and not future.done():
                future.set_result(None)

    async def _wait_value(self, ref: IORef, wanted: int, timeout_s: float, what: str) -> None:
        key = (ref.module, ref.point)
        if self.values.get(key) == wanted:
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        entry = (wanted, future)
        self._waiters.setdefault(key, []).append(entry)
        try:
            await asyncio.wait_for(future, timeout_s)
        except TimeoutError:
            why = self._module_note(ref)
            raise CommandError(f"{what} not confirmed within {timeout_s:g} s{why}") from None
        finally:
            self._waiters[key].remove(entry)

    def _module_note(self, ref: IORef) -> str:
        health = self.pollers[ref.module].health
        return f"; module {ref.module} is {health.state.value}" if not health.online else ""

    async def _wait_cabin(self, elevator: Elevator, stop: ElevatorStop, what: str) -> None:
        """Until the cabin is at ``stop`` with its door open. A busy cabin first ends its trip,
        holds its door at other floors, then comes (a ride is longer than ``travel_time_s``):
        the call fails only when the cabin shows no progress (it neither arrives at nor
        leaves any stop) for ``travel_time_s`` plus the margin: a stuck cabin, an offline
        module."""
        window = elevator.travel_time_s + self.command_margin_s
        since = time.monotonic()
        while True:
            left = since + window - time.monotonic()
            try:
                await self._wait_value(stop.in_position, 1, max(left, 0.0), what)
                return
            except CommandError:
                moved = self._moved.get(elevator.id, 0.0)
                if moved <= since:
                    why = self._module_note(stop.in_position)
                    raise CommandError(
                        f"{what} not confirmed: the cabin showed no progress for {window:g} s{why}"
                    ) from None
                since = moved

    # -- commands ------------------------------------------------------------------------------

    def _spawn(
        self, message: Message, handler: Callable[[Message], Awaitable[dict[str, Any]]]
    ) -> None:
        """Bus handlers must not block: each command runs as its own task (bounded)."""
        if len(self._commands) >= MAX_COMMANDS:
            self._fail(message, f"building interface busy ({MAX_COMMANDS} commands in progress)")
            return
        task = asyncio.create_task(self._run_command(message, handler))
        self._commands.add(task)
        task.add_done_callback(self._commands.discard)

    async def _run_command(
        self, message: Message, handler: Callable[[Message], Awaitable[dict[str, Any]]]
    ) -> None:
        try:
            await handler(message)
        except ValidationError as exc:
            self._fail(message, f"bad payload: {exc.errors()[0]['msg']}")
        except CommandRefused as exc:
            self._fail(message, str(exc), refused=True)
        except (CommandError, ModbusIOError) as exc:
            self._fail(message, str(exc))

    def _reply(self, request: Message, type_name: str, payload: dict[str, Any]) -> None:
        """Confirm to the requester only: everyone else hears the device's own state change."""
        if request.source:
            self.endpoint.publish(
                type_name, payload, destination=request.source, correlation_id=request.id
            )

    def _fail(self, request: Message, reason: str, *, refused: bool = False) -> None:
        log.info(
            "%s from %s %s: %s",
            request.type,
            request.source,
            "refused" if refused else "failed",
            reason,
        )
        payload = CommandFailed(
            command=request.type, reason=reason, target=_target(request), refused=refused
        )
        if request.source:
            self.endpoint.publish(payload, destination=request.source, correlation_id=request.id)
        else:
            self.endpoint.publish(payload)

    async def _write(self, ref: IORef, value: int) -> None:
        module, point = self.config.resolve(ref)
        poller = self.pollers[module.id]
        if poller.health.state == HealthState.offline:
            raise CommandError(
                f"module {module.id} is offline ({poller.health.last_error or 'no answer'})"
            )
        await poller.client.write(point.kind, point.address, value)

    def _door(self, door_id: str) -> Door:
        door = next((d for d in self.config.doors if d.id == door_id), None)
        if door is None:
            known = ", ".join(d.id for d in self.config.doors) or "none"
            raise CommandError(f"unknown door {door_id!r} (known: {known})")
        return door

    def _check_gate(self, node: str) -> None:
        if self.gate is not None and (reason := self.gate(node)) is not None:
            raise CommandRefused(reason)

    def drop_door_holders(self, nodes: set[str], evacuating: Collection[str] = ()) -> list[str]:
        """Release every holder of the doors at ``nodes`` and close them (the fire alarm:
        docs/emergency.md); the ids of the doors that were held. ``evacuating``: the robots
        the alarm sends to safety."""
        dropped = []
        for keeper in self.doors.values():
            if keeper.door.node in nodes and keeper.holders:
                # The open_door requests still waiting of the robots evacuating are withdrawn,
                # not failed: a time-out would close the door as trouble and raise an alert
                # mid-evacuation. A robot outside the zone still wants the door: it is told at
                # once that the alarm holds it (it waited its whole wait_timeout_s, unanswered).
                refusal = (self.gate(keeper.door.node) if self.gate is not None else None) or (
                    "fire alarm: its zone's doors are closed"
                )
                keeper.release_all(
                    withdraw="the fire alarm dropped its holders",
                    refuse=refusal,
                    spare=evacuating,
                )
                dropped.append(keeper.door.id)
                task = asyncio.get_running_loop().create_task(self._close(keeper, best_effort=True))
                self._commands.add(task)
                task.add_done_callback(self._commands.discard)
        return dropped

    async def _open_door(self, message: Message) -> dict[str, Any]:
        """Hold the door open for the requester until it sends release_door."""
        open_door: OpenDoor = message.typed(OpenDoor)
        door = self._door(open_door.door)
        self._check_gate(door.node)
        keeper = self.doors[door.id]
        holder = message.source or "anonymous"
        keeper.hold(holder, functools.partial(self._hold_expired, door.id, holder))
        try:
            await self._write(door.open, 1)
            keeper.coil_set(time.monotonic())
            timeout = door.open_time_s + self.command_margin_s
            try:
                await keeper.wait_open(timeout, holder)
            except DoorReleased as withdrawn:  # no failure of the door
                log.info("door %s: %s's open_door withdrawn: %s", door.id, holder, withdrawn)
                if isinstance(withdrawn, DoorShut):  # the requester still waits: it may ask again
                    self._reply(message, "door_closed", {"door": door.id})
                return {"door": door.id}
            except DoorRefused as refused:  # its hold is gone already, the door closing
                self._fail(message, str(refused), refused=True)
                return {"door": door.id}
            except TimeoutError:
                health = self.pollers[door.open.module].health
                why = f"; module {door.open.module} is {health.state.value}"
                raise CommandError(
                    f"door {door.id} not open within {timeout:g} s"
                    + (why if not health.online else "")
                ) from None
        except BaseException:
            if keeper.release(holder):
                await self._close(keeper, best_effort=True)
            raise
        payload = {"door": door.id}
        self._reply(message, "door_opened", payload)
        return payload

    async def _release_door(self, message: Message) -> dict[str, Any]:
        release: ReleaseDoor = message.typed(ReleaseDoor)
        door = self._door(release.door)
        keeper = self.doors[door.id]
        if keeper.release(message.source or "anonymous"):
            await self._close(keeper)
        return {"door": door.id}

    def _hold_expired(self, door_id: str, holder: str) -> None:
        keeper = self.doors[door_id]
        log.warning(
            "door %s: %s held it longer than %g s, hold dropped",
            door_id,
            holder,
            keeper.door.max_hold_s,
        )
        self._let_go(keeper, holder)

    def _on_robot_state(self, message: Message, state: RobotState) -> None:
        """A robot whose agent restarted (a new ``boot_id``, backend/traffic/restarts.py): the
        doors its old process held open are let go at once, but the one it stands in."""
        robot, node = state.robot, state.node
        if robot != message.source or node is None:
            return
        if self.boots.restarted(robot, state.boot_id) is None:
            return
        for keeper in self.doors.values():
            if robot in keeper.holders and keeper.door.node != node:
                log.warning(
                    "door %s: %s's agent restarted (the process that held it is gone) and "
                    "reports %s: hold dropped",
                    keeper.door.id,
                    robot,
                    node,
                )
                self._let_go(keeper, robot)

    def _let_go(self, keeper: DoorKeeper, holder: str) -> None:
        """Drop ``holder``'s hold; the door closes when nobody else holds it."""
        if keeper.release(holder):
            task = asyncio.get_running_loop().create_task(self._close(keeper, best_effort=True))
            self._commands.add(task)
            task.add_done_callback(self._commands.discard)

    async def _clear_left_coil(self, keeper: DoorKeeper) -> None:
        """The door's module is back with the coil we could not clear still set: clear it,
        unless a robot asked for the door since. Its ``open_door`` may already have been
        answered (the door is physically open): closing under it would shut the door on a
        robot told to drive through (the soak saw it)."""
        if keeper.holders:
            log.info("door %s: module back, held again: its coil stays set", keeper.door.id)
        elif keeper.coil_left_set:
            log.info("door %s: module back, clearing its coil", keeper.door.id)
            await self._close(keeper, best_effort=True)

    async def _close(self, keeper: DoorKeeper, *, best_effort: bool = False) -> None:
        """Clear the open coil; the door counts as closed from this moment on."""
        keeper.closing()
        try:
            await self._write(keeper.door.open, 0)
        except (CommandError, ModbusIOError) as exc:
            keeper.clear_failed()
            if not best_effort:
                raise
            log.warning(
                "door %s: could not clear its coil (cleared when its module is back): %s",
                keeper.door.id,
                exc,
            )
        except BaseException:
            keeper.clear_failed()
            raise
        else:
            keeper.cleared(time.monotonic())

    async def _close_door(self, message: Message) -> dict[str, Any]:
        """Close now, whoever holds the door (staff). The open_door requests still waiting
        for it are answered ``door_closed``, not failed: no trouble closure and no alert for a
        door staff closed on purpose, and a robot waiting in front knows to ask again."""
        close_door: CloseDoor = message.typed(CloseDoor)
        door = self._door(close_door.door)
        keeper = self.doors[door.id]
        keeper.release_all(shut=f"staff closed door {door.id}")
        await self._close(keeper)
        if door.is_open is not None:
            timeout = door.open_time_s + self.command_margin_s
            await self._wait_value(door.is_open, 0, timeout, f"door {door.id} closing")
        payload = {"door": door.id}
        self._reply(message, "door_closed", payload)
        return payload

    async def _call_elevator(self, message: Message) -> dict[str, Any]:
        call: CallElevator = message.typed(CallElevator)
        elevator = next((e for e in self.config.elevators if e.id == call.elevator), None)
        if elevator is None:
            known = ", ".join(e.id for e in self.config.elevators) or "none"
            raise CommandError(f"unknown elevator {call.elevator!r} (known: {known})")
        stop = next((s for s in elevator.stops if s.floor == call.floor), None)
        if stop is None:
            floors = ", ".join(s.floor for s in elevator.stops)
            raise CommandError(f"elevator {elevator.id} has no floor {call.floor!r} ({floors})")
        for each in elevator.stops:  # a ride ends on another floor: every stop must be free
            self._check_gate(each.node)
        await self._write(stop.call, 1)
        await self._wait_cabin(elevator, stop, f"elevator {elevator.id} at floor {stop.floor}")
        payload = {"elevator": elevator.id, "floor": stop.floor, "door_open": True}
        self._reply(message, "elevator_in_position", payload)
        return payload

    async def _set_output(self, message: Message) -> dict[str, Any]:
        """Write an output; the new value shows in building_input_changed once read back."""
        command: SetOutput = message.typed(SetOutput)
        ref = IORef(module=command.module, point=command.point)
        try:
            _, point = self.config.resolve(ref)
        except KeyError:
            raise CommandError(f"no point {command.point!r} on module {command.module!r}") from None
        if not allowed(Role.output, point.kind):
            raise CommandError(
                f"{command.module}.{command.point} is a {point.kind.value}: read-only"
            )
        value = int(command.value)
        if point.kind == PointKind.coil and value not in (0, 1):
            raise CommandError(f"coil {command.module}.{command.point} takes 0/1, got {value}")
        if not 0 <= value <= 0xFFFF:
            raise CommandError(f"register value {value} is outside 0..65535")
        await self._write(ref, value)
        return {"module": command.module, "point": command.point, "value": value}


def _target(request: Message) -> str | None:
    """What a command was for, as alerts name it: a door, an elevator, ``module/point``."""
    p = request.payload
    for key in ("door", "elevator"):
        if isinstance(p.get(key), str):
            return str(p[key])[:64]
    if isinstance(p.get("module"), str) and isinstance(p.get("point"), str):
        return f"{p['module']}/{p['point']}"[:129]
    return None
