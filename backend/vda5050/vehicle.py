"""One VDA 5050 vehicle in the fleet: a hub endpoint named after the robot that does, for the
Task and Traffic Managers, what GuideBot's robot agent does (task reports, paths, areas, doors,
``robot_state``), and turns it into ``order`` and ``instantActions`` for the vehicle
(docs/vda5050.md)."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections import deque
from collections.abc import Awaitable, Callable, Coroutine, Mapping
from dataclasses import replace
from datetime import datetime
from typing import Any

from backend.vda5050.order import (
    build_order,
    init_position,
    instant_actions,
    node_seq,
    step_of_seq,
)
from backend.vda5050.pauses import PAUSE_EVENT, PauseOwner
from backend.vda5050.zones import area_boxes, inside, responses, zone_sets
from guidebot.bus import BusEndpoint, RequestTimeout
from guidebot.messages import Message
from guidebot.payloads.building import (
    CallElevator,
    DoorClosed,
    DoorOpened,
    ElevatorInPosition,
    OpenDoor,
    ReleaseDoor,
)
from guidebot.payloads.robot import (
    ENDED_REPORTED,
    BatteryAlarm,
    EndedTask,
    NodeReached,
    RobotFault,
    RobotMode,
    RobotState,
)
from guidebot.payloads.tasks import (
    RobotLink,
    TaskAssigned,
    TaskEnded,
    TaskStarted,
    TourProgress,
)
from guidebot.payloads.traffic import (
    AreaGranted,
    ClosuresChanged,
    GetPath,
    ReleaseArea,
    RequestArea,
)
from guidebot.site.schema import RobotConfig, Site
from guidebot.vda5050.schemas import version_of
from guidebot.vda5050.sim import speak_seconds
from guidebot.vda5050.topics import Vehicle

__all__ = ["DriveFailed", "VdaRobot", "vehicle_of"]

log = logging.getLogger(__name__)

Send = Callable[[str, dict[str, Any]], Awaitable[bool]]
"""Publish a message on one of the vehicle's topics (``order``, ``instantActions``)."""
TaskOf = Callable[[str], tuple[str, dict[str, Any]] | None]
"""The net and parameters of a task the Task Manager has this robot on (not ended), or None:
what a new master control (a new leader, a restarted server) resumes a vehicle's order with."""
StepOf = Callable[[str], dict[str, Any]]
"""A site node as a path step ({node, floor, x, y, door, elevator, area})."""
Holder = Callable[[str], str | None]
"""The robot the lock table gives an area to now (None: nobody)."""
Gate = Callable[[str, str], str | None]
"""(robot, area) -> why the robot may not have the area now (the fire alarm), or None."""
Record = Callable[[str, dict[str, Any]], None]
"""Write a row of the event log (kind, data): what a new master control reads back."""

ACK_TIMEOUT_S = 3.0
"""An order the vehicle's state does not name this long after it was sent is sent again."""
ORDER_TRIES = 3
"""Sends of one order before the task fails: never resent forever. Only sends the vehicle could
hear count: the broker took them and the vehicle has been heard since the master control's
last loss of the broker (``VdaRobot.heard``)."""
SILENCE_S = 60.0
"""A vehicle that says nothing (no state, connection or factsheet) this long is taken as a
broken connection: VDA 5050 asks for a state at least every 30 s, and a vehicle whose software
hangs, or that never came back after a broker outage, leaves no last will."""
DONE_ACTIONS = frozenset({"FINISHED", "FAILED"})
REPORTED_LEVELS = frozenset({"WARNING", "URGENT", "CRITICAL", "FATAL"})
"""Error levels that become a robot_fault (2.1.0 has WARNING and FATAL; 3.0.0 adds URGENT and
CRITICAL)."""
FAULT_LEVELS = frozenset({"CRITICAL", "FATAL"})
"""Error levels that put the robot in mode fault: it cannot go on with its order."""
BATTERY_REARM = 0.05
CHARGED = 0.95
"""A charge task ends at this battery level (as the robot agent's dock: robot_agent/battery.py)."""
RECALL_S = 2.0
"""While a vehicle waits for a cabin, drives into it or out of it, its call is repeated this
often (wall seconds), as a person keeps the button pressed: the building's door hold does not
run out under it."""


DOOR_ASK_S = 10.0
"""A door asked for and not answered (the building refused it, or it did not open in time)
is asked again this often (wall seconds)."""


class DriveFailed(Exception):
    """A goal the vehicle cannot reach, with the reason the task fails with."""


class OrderLost(Exception):
    """The vehicle's state no longer names the order it had taken (it restarted, or lost it
    while its connection was down): the drive is planned again from where it stands."""


REPLANS = 3
"""Times one goal is planned again after the vehicle lost its order, before the task fails."""
STALE_IN_ROW = 3
"""States older than the last one (``VdaRobot._stale``) ignored in a row: one delivered late
is ignored, but a vehicle that keeps saying so (it restarted with an older order) is
believed."""


def vehicle_of(config: RobotConfig) -> Vehicle:
    """The vehicle's names on the broker, from its site entry."""
    assert config.manufacturer is not None and config.serial_number is not None
    return Vehicle(
        manufacturer=config.manufacturer,
        serial_number=config.serial_number,
        interface=config.mqtt_interface,
        version=config.vda_version,
    )


class VdaRobot:
    """The robot ``config.name`` on the hub (``endpoint``), the vehicle behind ``send``."""

    def __init__(
        self,
        config: RobotConfig,
        site: Site,
        endpoint: BusEndpoint,
        announce: BusEndpoint,
        send: Send,
        *,
        task_of: TaskOf | None = None,
        step_of: StepOf | None = None,
        holder: Holder | None = None,
        gate: Gate | None = None,
        record: Record | None = None,
        paused_by: PauseOwner | None = None,
    ) -> None:
        self.name = config.name
        self.record = record
        self.restored_pause = paused_by.device if paused_by is not None else None
        """The last master control's own pause of the vehicle (the event log's word): taken
        up again when this one goes on with the vehicle's order (``_adopt``)."""
        self.holder = holder
        self.gate = gate
        self.task_of = task_of
        self.step_of = step_of
        self.vehicle = vehicle_of(config)
        self.map_ids: Mapping[str, str] = config.map_ids
        self.floor_of_map = {config.map_ids.get(f.id, f.id): f.id for f in site.floors}
        self.nodes = {n.id: n for n in site.nodes}
        self.area_nodes = {a.id: frozenset(a.nodes) for a in site.areas}
        self.boxes = area_boxes(site)
        self.site = site
        self.v3 = False
        self.zone_sets: dict[str, dict[str, Any]] = {}
        """3.x: the restricted areas as RELEASE zones, one zone set per floor."""
        self.zone_area: dict[tuple[str, str], str] = {}
        """(zoneSetId, zoneId) of a RELEASE zone, of every set given -> its area."""
        self.closed: frozenset[str] = frozenset()
        """The nodes closed to robots now (closures_changed): BLOCKED zones."""
        self.supported_zones: frozenset[str] | None = None
        """The zone types the vehicle's factsheet says it understands (None: not said)."""
        self._confirmed: set[str] = set()
        """Areas the lock table was seen to give this robot: one it then gives to another or
        to nobody while we still count it ours was taken back (a staff release)."""
        self.zone_requests: dict[str, str] = {}
        """The vehicle's open ACCESS zone requests: requestId -> area."""
        self._answered: dict[str, str] = {}
        self._zones_sent: set[str] = set()
        self.ep = endpoint
        self.announce = announce
        self.send = send
        self.node: str | None = config.start_node
        self.floor: str | None = self.nodes[self.node].floor if self.node in self.nodes else None
        self.state: dict[str, Any] | None = None
        self.online = False
        self.heard = False
        """The vehicle has spoken since the master control last lost the broker: what is sent
        now can reach it (a vehicle still reconnecting after an outage hears nothing)."""
        self.heard_at = -math.inf
        """When the vehicle last spoke (the loop's clock): ``check_silence``."""
        self.hibernating = False
        """3.0.0: the vehicle says HIBERNATING (connected, silent, not moving)."""
        self.task_id: str | None = None
        self.runner: asyncio.Task[None] | None = None
        self.cancelling: str | None = None
        """The task a cancel is ending (its runner winds down)."""
        self.held: Message | None = None
        """An assignment that came while the cancelled task wound down: started after it."""
        self.order_id: str | None = None
        self.granted: set[str] = set()
        self.requested: set[str] = set()
        self.kept: dict[str, str | None] = {}
        """Areas kept at a task's end because the vehicle may be inside them (its last node's
        and its next node's: a cancelOrder stops it "as soon as possible", on an edge too),
        with the node it was last at then; released once a state shows it out
        (``_release_kept``)."""
        self.doors: set[str] = set()
        """Doors asked for (open_door sent) and not released."""
        self.open_doors: set[str] = set()
        self.door_asks: dict[str, tuple[str, float]] = {}
        """Door -> (id of our last open_door, when sent), until the building answers it."""
        self.held_doors: set[str] = set()
        """Doors the building has answered our open_door for and not closed since: it holds
        them open for us. Only these are passed: another robot's opening may end (its
        release_door handled before our open_door) after the base is released through the
        door (``_releasable``)."""
        self.paused_for: tuple[str, str] | None = None
        """("door", id) on the released base ahead that closed under the vehicle's hold, or
        ("elevator", id) whose cabin the vehicle is getting out of and that is no longer open
        at its floor: the master paused the vehicle (``startPause``) until it is open again
        (``_guard_base``)."""
        self.paused_at = -math.inf
        self.staff_paused = paused_by.staff if paused_by is not None else False
        """Staff paused the vehicle (``pause``): a door's ``stopPause`` does not let it go on.
        Read back from the event log by a new master control."""
        self.route: dict[int, str] = {}
        """The current order's nodes ahead by sequence id (``_reached``)."""
        self.route_seq = 0
        self.placed: str | None = None
        """The node an ``initPosition`` put the vehicle on (after a ride), until a state of
        the vehicle names it: a state sent before it, read after, names the cabin left."""
        self.cabins: dict[str, tuple[str, bool]] = {}
        """Elevator -> (floor, door open), from the building's elevator_in_position."""
        self.recall_s = RECALL_S
        self.factsheet: dict[str, Any] | None = None
        self.speaks = True
        """Tour stops are ``speak`` actions (until a factsheet says the vehicle has none:
        then a ``wait`` as long as the text takes to say)."""
        self._tasks: set[asyncio.Task[Any]] = set()
        self.closing = False
        """The server stops: a running task is left as it is (not reported ended)."""
        self.battery_low, self.battery_panic = config.battery_low, config.battery_panic
        self._alarm: str | None = None
        """The battery alarm sent and not yet re-armed (``battery_low`` or ``battery_panic``)."""
        self._called: dict[tuple[str, str], float] = {}
        self.waiting: str | None = None
        self.changed = asyncio.Event()
        self.ended: deque[EndedTask] = deque(maxlen=ENDED_REPORTED)
        self.faults: set[tuple[str, str]] = set()
        self.seq = 0
        self._headers: dict[str, int] = {}
        self._stale_in_row = 0
        self._orders = 0
        self._speak(self.vehicle.version)
        self._unsubscribe = [
            endpoint.on(TaskAssigned, self._on_task_assigned),
            # Read as JSON: a cancel is obeyed whatever else its payload carries.
            endpoint.subscribe("task_cancel", self._on_task_cancel),
            endpoint.on(AreaGranted, self._on_area_granted),
            endpoint.on(DoorOpened, self._on_door),
            endpoint.on(DoorClosed, self._on_door),
            endpoint.on(ElevatorInPosition, self._on_cabin),
            endpoint.on(ClosuresChanged, self._on_closures),
        ]

    def use_site(self, site: Site, config: RobotConfig) -> None:
        """A published site (same vehicle, same names): its maps, nodes, areas, zones and
        battery thresholds from now on; a task running keeps its path."""
        self.site = site
        self.map_ids = config.map_ids
        self.floor_of_map = {config.map_ids.get(f.id, f.id): f.id for f in site.floors}
        self.nodes = {n.id: n for n in site.nodes}
        self.area_nodes = {a.id: frozenset(a.nodes) for a in site.areas}
        self.boxes = area_boxes(site)
        self.battery_low, self.battery_panic = config.battery_low, config.battery_panic
        if self.v3:  # new zones have new ids: given to the vehicle with its next state
            self._refresh_zones()

    async def close(self) -> None:
        self.closing = True
        for unsubscribe in self._unsubscribe:
            unsubscribe()
        for task in list(self._tasks):
            task.cancel()
        if self.runner is not None:
            self.runner.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self.runner

    # -- to the vehicle --------------------------------------------------------------------
    def _header_id(self, topic: str) -> int:
        self._headers[topic] = self._headers.get(topic, -1) + 1
        return self._headers[topic]

    async def instant(
        self, *kinds: str, parameters: Mapping[str, Any] | None = None
    ) -> dict[str, Any]:
        """Send one ``instantActions`` with these action types; returns it."""
        n = self._header_id("instantActions")
        message = instant_actions(
            self.vehicle,
            n,
            [(f"{self.name}-{kind}-{n}", kind) for kind in kinds],
            parameters,
        )
        await self.send("instantActions", message)
        return message

    # -- from the vehicle ------------------------------------------------------------------
    def broker_lost(self) -> None:
        """The master control lost the broker: the vehicle may be still away once it is back
        (its own reconnection has a back-off), so order sends do not count until it speaks."""
        self.heard = False

    def check_silence(self) -> None:
        """Called every second: an online vehicle silent for ``SILENCE_S`` is disconnected
        (the Task Manager's grace period, then its task back in the queue), as a broken
        connection's last will would have done."""
        silent = asyncio.get_running_loop().time() - self.heard_at
        if self.online and silent > SILENCE_S:
            self.on_connection(
                {"connectionState": "CONNECTIONBROKEN"},
                why=f"silent for {silent:.0f} s (VDA 5050: a state at least every 30 s)",
            )

    def _spoke(self) -> None:
        self.heard = True
        self.heard_at = asyncio.get_running_loop().time()

    def on_connection(self, message: dict[str, Any], why: str | None = None) -> None:
        """The vehicle's ``connection`` topic; ``why``: the master's own reason instead (a
        silent vehicle)."""
        if why is None:
            self._spoke()
        state = message["connectionState"]
        was = self.online
        self.online = state == "ONLINE"
        sleeping = state == "HIBERNATING"
        if sleeping != self.hibernating:
            self.hibernating = sleeping
            log.info("%s: %s", self.name, "hibernating" if sleeping else "no longer hibernating")
        if sleeping:
            # Connected, silent, its order cleared (6.2.3): offline to the fleet (never
            # dispatched, its task back in the queue after the grace period) after a clean
            # goodbye (no robot_lost alert), its navigation "hibernating" in the console.
            self._publish_state()
            if was:
                self.announce.publish("robot_disconnected", RobotLink(robot=self.name))
        elif self.online and not was:
            self._zones_sent.clear()
            self.announce.publish("robot_connected", RobotLink(robot=self.name))
            self._spawn(self.instant("stateRequest", "factsheetRequest"))
        elif not self.online and was:
            log.warning("%s: %s", self.name, why or f"the vehicle's connection is {state}")
            if state == "OFFLINE":  # a clean goodbye
                self._publish_state()
            self.announce.publish("robot_disconnected", RobotLink(robot=self.name))
        self.changed.set()

    def _spawn(self, coro: Coroutine[Any, Any, Any]) -> None:
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _speak(self, version: str) -> None:
        """Speak the vehicle's version: the one its site entry says, then the one its own
        messages declare (``version``: 2.x or 3.x) when they say another. 3.x gets zones."""
        wanted = version_of({"version": version}, self.vehicle.version)
        if wanted != self.vehicle.version:
            log.warning(
                "%s: the vehicle speaks VDA 5050 %s (its site entry says %s): followed",
                self.name,
                version,
                self.vehicle.version,
            )
            self.vehicle = replace(self.vehicle, version=wanted)
        self.v3 = wanted.startswith("3.")
        if self.v3 and not self.zone_sets:
            self._refresh_zones()

    def on_factsheet(self, message: dict[str, Any]) -> None:
        """What the vehicle can do: whether a tour stop is a ``speak`` or a timed ``wait``."""
        self._spoke()
        self._speak(str(message["version"]))
        self.factsheet = message
        features = message["protocolFeatures"]
        actions = features.get("agvActions") or features.get("mobileRobotActions") or []
        self.speaks = any(
            a["actionType"] == "speak" and "NODE" in a["actionScopes"] for a in actions
        )
        supported = message["typeSpecification"].get("supportedZones")
        if supported is not None and self.v3:
            self.supported_zones = frozenset(supported)
            self._refresh_zones()
        log.info(
            "%s: factsheet of %s: tour stops by %s",
            self.name,
            message["typeSpecification"].get("seriesName", "?"),
            "speech (speak)" if self.speaks else "a timed wait (no speak action)",
        )

    def on_state(self, message: dict[str, Any]) -> None:
        self._spoke()
        if self.hibernating:  # sent before it fell asleep: it speaks again after ONLINE
            return
        if self._stale(message) and self._stale_in_row < STALE_IN_ROW:
            self._stale_in_row += 1
            log.info(
                "%s: a state older than the last one ignored (order %s, update %s, at %s)",
                self.name,
                message.get("orderId"),
                message.get("orderUpdateId"),
                message.get("lastNodeId"),
            )
            return
        self._stale_in_row = 0
        if not self.online:
            self.on_connection({"connectionState": "ONLINE"})
        self._speak(str(message["version"]))
        self.state = message
        if self.task_id is None and self.runner is None:
            self._adopt(message)
        position = _position(message)
        if position is not None:
            self.floor = self.floor_of_map.get(position["mapId"], self.floor)
        at = datetime.fromisoformat(message["timestamp"]).timestamp()
        for node in self._reached(message):
            if node == self.node:
                continue
            self._left(self.node, node)
            self.node = node
            self.floor = self.nodes[node].floor
            self.ep.publish(NodeReached(robot=self.name, node=node, floor=self.floor, at=at))
            if self.closed and self.v3:  # its own place is never BLOCKED to it
                self._refresh_zones()
        self._release_kept(message)
        self._report_errors(message["errors"])
        self._battery(_battery(message)[0] / 100)
        if self.v3:
            self._zones(message)
        self._publish_state()
        self.changed.set()

    def _stale(self, state: Mapping[str, Any]) -> bool:
        """A state older than the last one taken: it names an earlier order of the same task
        (orders of a task are ``<task id>-<n>``, and a vehicle never goes back to an older
        one), or the same order at an earlier update. A report the broker delivers late, after
        a broken connection: taken, it moved the robot back and made the master think the
        vehicle had lost its order, and send a new one from a node the vehicle had left
        ("order refused: still driving an order", "not at hall")."""
        last = self.state
        if last is None:
            return False
        new_id, old_id = str(state.get("orderId") or ""), str(last.get("orderId") or "")
        if new_id and new_id == old_id:
            return int(state.get("orderUpdateId", 0)) < int(last.get("orderUpdateId", 0))
        new, old = _order_number(new_id), _order_number(old_id)
        return new is not None and old is not None and new[0] == old[0] and new[1] < old[1]

    # -- 3.0.0 zones -----------------------------------------------------------------------
    def _refresh_zones(self) -> None:
        """The zone sets for the site, its closures and the vehicle's supported zone types.
        The closed nodes where the vehicle is (its node, its area) are left out of BLOCKED:
        a vehicle inside a BLOCKED zone must stop with a CRITICAL error, and it has to get
        out; the zones are made again as it moves."""
        here = {self.node} if self.node else set()
        for members in self.area_nodes.values():
            if self.node in members:
                here |= members
        before = {f: zs["zoneSetId"] for f, zs in self.zone_sets.items()}
        self.zone_sets = zone_sets(
            self.site, self.map_ids, closed=self.closed - here, supported=self.supported_zones
        )
        for floor, zs in self.zone_sets.items():
            if before.get(floor) != zs["zoneSetId"]:  # enabled again if it was given before
                self._zones_sent.discard(zs["zoneSetId"])
        self.zone_area.update(
            {
                (zs["zoneSetId"], z["zoneId"]): str(z["zoneId"])
                for zs in self.zone_sets.values()
                for z in zs["zones"]
                if z["zoneType"] == "RELEASE"
            }
        )

    def _on_closures(self, msg: Message, changed: ClosuresChanged) -> None:
        """Closed nodes changed: new zone sets (BLOCKED) given at once, and granted zone
        requests for a closed area revoked."""
        closed = frozenset(changed.nodes)
        if closed == self.closed:
            return
        self.closed = closed
        if self.v3:
            self._refresh_zones()
            if self.online and self.state is not None:
                self._zones(self.state)

    def _zone_refusal(self, area: str) -> str | None:
        """Why the vehicle may not be in ``area`` now: closed, the fire alarm's, or taken
        back from it by the lock table (a staff release); None: it may."""
        if self.closed & self.area_nodes.get(area, frozenset()):
            return f"area {area} is closed to robots"
        refusal = self.gate(self.name, area) if self.gate is not None else None
        if refusal:
            return refusal
        if self.holder is None or area not in self.granted:
            return None
        holder = self.holder(area)
        if holder == self.name:
            self._confirmed.add(area)
        elif area in self._confirmed:
            self._confirmed.discard(area)
            self.granted.discard(area)
            self.requested.discard(area)
            return f"the lock table gave area {area} to {holder or 'nobody'} (released by staff)"
        return None

    def _zones(self, state: dict[str, Any]) -> None:
        """Give the vehicle the site's zone sets (``zoneSet``, then ``enableZoneSet``) unless
        it reports them enabled, and answer its zone requests through the lock table."""
        have = {z["zoneSetId"]: z["zoneSetStatus"] for z in state.get("zoneSets") or []}
        for zone_set in self.zone_sets.values():
            zid = zone_set["zoneSetId"]
            if have.get(zid) == "ENABLED" or zid in self._zones_sent:
                continue
            self._zones_sent.add(zid)
            self._spawn(self._give_zone_set(zone_set, upload=zid not in have))
        self._zone_requests(state.get("zoneRequests") or [])

    async def _give_zone_set(self, zone_set: dict[str, Any], *, upload: bool) -> None:
        if upload:
            header = self.vehicle.header(self._header_id("zoneSet"))
            await self.send("zoneSet", {**header, "zoneSet": zone_set})
        await self.instant("enableZoneSet", parameters={"zoneSetId": zone_set["zoneSetId"]})

    def _zone_requests(self, requests: list[dict[str, Any]]) -> None:
        """An ACCESS request for one of our zones is a ``request_area``: answered QUEUED,
        then GRANTED when the Traffic Manager grants the area (at once if the robot holds
        it); any other request REJECTED. A granted request the vehicle drops (it left the
        zone) gives the area back when no task of ours holds it."""
        now: dict[str, str] = {}
        for request in requests:
            rid = str(request["requestId"])
            area = self.zone_area.get((request["zoneSetId"], request["zoneId"]))
            if request["requestType"] != "ACCESS" or area is None:
                self._answer(rid, "REJECTED")
                continue
            now[rid] = area
            refusal = self._zone_refusal(area)
            if request["requestStatus"] == "GRANTED" and refusal is not None:
                if self._answered.get(rid) != "REVOKED":
                    log.warning("%s: zone request %s revoked: %s", self.name, rid, refusal)
                self._answer(rid, "REVOKED")
                continue
            if request["requestStatus"] != "REQUESTED":
                continue  # GRANTED: inside; REVOKED, EXPIRED: its own business
            if refusal is not None and self._answered.get(rid) != "GRANTED":
                self._answer(rid, "REJECTED")
                continue
            if area in self.granted:
                self._answer(rid, "GRANTED")
                continue
            self.zone_requests[rid] = area  # a grant may come inside the publish below
            if area not in self.requested:
                self.requested.add(area)
                self.ep.publish(RequestArea(robot=self.name, area=area))
            if self._answered.get(rid) != "GRANTED":
                self._answer(rid, "GRANTED" if area in self.granted else "QUEUED")
        for rid, area in self.zone_requests.items():
            if rid in now or area in now.values() or self.task_id is not None:
                continue
            if area in self.granted | self.requested and not self._stands_in(area, self.node):
                self._release_area(area)
        self._answered = {r: g for r, g in self._answered.items() if r in now}
        self.zone_requests = now

    def _answer(self, request_id: str, grant: str) -> None:
        if self._answered.get(request_id) == grant:
            return
        self._answered[request_id] = grant
        message = responses(self.vehicle, self._header_id("responses"), [(request_id, grant)])

        async def send() -> None:
            await self.send("responses", message)

        self._spawn(send())

    def _reached(self, message: dict[str, Any]) -> list[str]:
        """The nodes reached since the last state, in order: a state is a sample, and a
        vehicle may pass several nodes of its order between two (every one is reported, for
        the area locks and the fleet's invariants)."""
        if self.order_id is not None and message.get("orderId") == self.order_id:
            # On our order its sequence ids are the progress, never lastNodeId alone: a state
            # sent before an elevator ride's initPosition, read after it, names the cabin on
            # the floor left (the fleet's invariants saw V1 "enter" a lift gone upstairs).
            seq = int(message["lastNodeSequenceId"])
            passed = [n for s, n in sorted(self.route.items()) if self.route_seq < s <= seq]
            if passed:
                self.route_seq = seq
            if message["lastNodeId"] == self.placed or passed:
                self.placed = None
            return passed
        last = str(message["lastNodeId"])
        if self.placed is not None:  # put on another floor: only its word on that node counts
            if last != self.placed:
                return []
            self.placed = None
        return [last] if last in self.nodes else []

    def _battery(self, level: float) -> None:
        """``battery_low`` / ``battery_panic`` once per crossing of the robot's thresholds, as
        the robot agent sends them (re-armed 0.05 above ``battery_low``)."""
        if level >= self.battery_low + BATTERY_REARM:
            self._alarm = None
        if level <= self.battery_panic and self._alarm != "battery_panic":
            self._alarm = "battery_panic"
        elif level <= self.battery_low and self._alarm is None:
            self._alarm = "battery_low"
        else:
            return
        log.warning("%s: %s at %.2f", self.name, self._alarm.replace("_", " "), level)
        alarm = BatteryAlarm(robot=self.name, level=round(max(0.0, min(1.0, level)), 3))
        self.ep.publish(self._alarm, alarm)

    def _report_errors(self, errors: list[dict[str, Any]]) -> None:
        now = {(e["errorType"], e.get("errorDescription", "")) for e in errors}
        for error in errors:
            key = (error["errorType"], error.get("errorDescription", ""))
            if key in self.faults or error["errorLevel"] not in REPORTED_LEVELS:
                continue
            detail = f"{error['errorLevel']} {error['errorType']}: {key[1]}".strip(": ")
            self.ep.publish(
                RobotFault(
                    robot=self.name, kind=f"vda5050_{error['errorType']}"[:64], detail=detail
                )
            )
        self.faults = now

    def _mode(self) -> RobotMode:
        state = self.state or {}
        if not self.online:
            return RobotMode.OFFLINE
        if any(e["errorLevel"] in FAULT_LEVELS for e in state.get("errors", [])):
            return RobotMode.FAULT
        if self.task_id is not None:
            return RobotMode.BUSY
        if _battery(state)[1]:
            return RobotMode.CHARGING
        return RobotMode.IDLE

    def _publish_state(self) -> None:
        state = self.state or {}
        position = _position(state) or {}
        node = self.nodes.get(self.node or "")
        battery = _battery(state)[0]
        velocity = state.get("velocity") or {}
        self.seq += 1
        self.ep.publish(
            RobotState(
                robot=self.name,
                x=float(position.get("x", node.x if node else 0.0)),
                y=float(position.get("y", node.y if node else 0.0)),
                theta=float(position.get("theta", 0.0)),
                node=self.node,
                floor=self.floor,
                battery=min(1.0, max(0.0, float(battery) / 100)),
                mode=self._mode(),
                navigation=self._navigation(state),
                task_id=self.task_id,
                speed=math.hypot(velocity.get("vx", 0.0), velocity.get("vy", 0.0)),
                areas=sorted(self.granted)[:64],
                ended=list(self.ended),
                seq=self.seq,
            )
        )

    def _navigation(self, state: Mapping[str, Any]) -> str:
        """``paused`` while the vehicle says it is (staff's pause, or its own pause button),
        else moving, else what it waits for."""
        if self.hibernating:
            return "hibernating"
        if state.get("paused") and (self.paused_for is None or self.staff_paused):
            return "paused"
        if self.paused_for is not None:
            return f"waiting_{self.paused_for[0]}"
        if state.get("driving"):
            return "moving"
        return self.waiting or "idle"

    async def hibernate(self, asleep: bool) -> None:
        """Staff send the vehicle to sleep (``startHibernation``: it clears its order, says
        HIBERNATING and stops reporting) or wake it (``stopHibernation``: ONLINE again)."""
        log.info("%s: %s", self.name, "sent to hibernate" if asleep else "woken up by staff")
        await self.instant("startHibernation" if asleep else "stopHibernation")

    async def pause(self, paused: bool) -> None:
        """Staff pause the vehicle where it stands (``startPause``) or let it go on
        (``stopPause``): its order is kept (docs/vda5050.md, "Pause"). Let go on while the
        master holds it before a door (or in a cabin) that closed under it, it goes on once
        that is open again."""
        log.info("%s: %s", self.name, "paused by staff" if paused else "resumed by staff")
        self.staff_paused = paused
        if not paused and self.paused_for is not None:
            log.info("%s: goes on once %s %s is open again", self.name, *self.paused_for)
            return
        await self.instant("startPause" if paused else "stopPause")

    # -- tasks -----------------------------------------------------------------------------
    def _on_task_assigned(self, msg: Message, assigned: TaskAssigned) -> None:
        if assigned.robot != self.name:
            return
        task_id = assigned.task_id
        if task_id == self.task_id:
            return  # the same task again
        if self.task_id is not None and self.task_id == self.cancelling:
            # The Task Manager preempts an errand: cancel, then assign. The cancelled task
            # winds down (cancelOrder, its locks given back) and ends; then this one starts.
            self.held = msg
            return
        if self.task_id is not None:
            self.ep.publish(
                TaskEnded(
                    task_id=task_id,
                    robot=self.name,
                    outcome="refused",
                    reason=f"robot busy with task {self.task_id}",
                )
            )
            return
        self.task_id = task_id
        self.ep.publish(TaskStarted(task_id=task_id, robot=self.name))
        self._start(task_id, self._run(task_id, assigned.net, dict(assigned.params)))

    def _start(self, task_id: str, run: Coroutine[Any, Any, None]) -> None:
        """Run ``task_id``; a runner cancelled before its first step (or again while it
        winds down) is ended by ``_runner_done``: every task ends once."""
        runner = asyncio.get_running_loop().create_task(run, name=f"vda5050 {self.name} {task_id}")
        self.runner = runner
        runner.add_done_callback(self._runner_done)

    def _runner_done(self, runner: asyncio.Task[None]) -> None:
        if runner is self.runner and runner.cancelled() and not self.closing and self.task_id:
            self._end(self.task_id, "cancelled", "cancelled")

    def _on_task_cancel(self, msg: Message) -> None:
        task_id = msg.payload.get("task_id")
        if self.held is not None and self.held.typed(TaskAssigned).task_id == task_id:
            self.held = None  # cancelled before it started: never started
            return
        if task_id != self.task_id or self.runner is None or task_id == self.cancelling:
            return  # not ours, or already winding down
        self.cancelling = task_id
        self.runner.cancel()

    async def _run(
        self,
        task_id: str,
        net: str,
        params: dict[str, Any],
        resume: dict[str, Any] | None = None,
    ) -> None:
        """Run a task; ``resume``: the vehicle's state when a new master control took over
        the task while the vehicle ran its order (``_adopt``)."""
        outcome, reason = "done", ""
        try:
            if resume is None:
                await self._take_over()
                if _battery(self.state or {})[1]:
                    await self.instant("stopCharging")
            points = params.get("points")
            if isinstance(points, list):
                first = 0 if resume is None else self._resumed_point(task_id, points, resume)
                for point in points[first:]:
                    await self._visit(task_id, point, str(params.get("lang") or ""), resume)
                    resume = None
            else:
                await self.drive(task_id, str(params["node"]), resume=resume)
                if net == "battery_charge":
                    await self._charge()
        except DriveFailed as exc:
            outcome, reason = "failed", str(exc)
            log.warning("%s: task %s failed: %s", self.name, task_id, reason)
        except asyncio.CancelledError:
            if self.closing:  # the server stops: the task and its locks stay, as for a robot
                raise
            outcome, reason = "cancelled", "cancelled"
            if self.order_id is not None:
                await self.instant("cancelOrder")
        self._end(task_id, outcome, reason)

    def _end(self, task_id: str, outcome: str, reason: str) -> None:
        """The task is over: doors and areas given back, ``task_ended``; then an assignment
        that came while it was being cancelled starts."""
        self._release_all()
        self.restored_pause = None
        if self.paused_for is not None:  # not left paused for the next task
            self._pause_for(None)
            if not self.staff_paused:
                self._spawn(self.instant("stopPause"))
        self.order_id = None
        self.route = {}
        self.placed = None
        self.waiting = None
        self.task_id = self.runner = self.cancelling = None
        self.ended.appendleft(EndedTask(task_id=task_id, outcome=outcome, reason=reason))  # type: ignore[arg-type]
        self.ep.publish(TaskEnded(task_id=task_id, robot=self.name, outcome=outcome, reason=reason))  # type: ignore[arg-type]
        self._publish_state()
        held, self.held = self.held, None
        if held is not None:
            self._on_task_assigned(held, held.typed(TaskAssigned))

    async def _charge(self) -> None:
        """At the station: ``startCharging``, and the task goes on until the battery is full
        (``stopCharging`` then), as a GuideBot robot's dock does, or until the vehicle stops
        charging by itself; one that never starts fails the task."""
        self.order_id = None  # its order is done: a cancel now has no order to cancel
        await self.instant("startCharging")
        loop = asyncio.get_running_loop()
        deadline = loop.time() + ACK_TIMEOUT_S * ORDER_TRIES
        started = False
        while True:
            self.changed.clear()
            level, charging = _battery(self.state or {})
            started = started or charging
            if level / 100 >= CHARGED:
                if charging:
                    await self.instant("stopCharging")
                return
            if started and not charging:
                log.info("%s stopped charging at %.0f %%", self.name, level)
                return
            if not started and loop.time() > deadline:
                raise DriveFailed(f"{self.name} did not start charging")
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(0.5):
                    await self.changed.wait()

    def _adopt(self, state: dict[str, Any]) -> None:
        """A new master control (a new leader, a restarted server) finds the vehicle on an
        order of a task the Task Manager still has it on (order ids are ``<task id>-<n>``):
        it goes on with that task from the vehicle's state, the same order extended by
        updates (no order lost, none sent twice), instead of cancelling it. The areas and
        doors on the vehicle's released base were granted to it: they are its own again."""
        order_id = str(state.get("orderId") or "")
        number = _order_number(order_id)
        if number is None or self.task_of is None or self.step_of is None:
            return
        task_id, n = number
        if any(e.task_id == task_id for e in self.ended):
            return  # ended here: the Task Manager has not heard it yet
        found = self.task_of(task_id)
        if found is None:
            return
        net, params = found
        self._orders = max(self._orders, n)
        here = [str(state["lastNodeId"])]
        ahead = [str(s["nodeId"]) for s in state.get("nodeStates", []) if s["released"]]
        for node in here + ahead:
            if node not in self.nodes:
                continue
            step = self.step_of(node)
            if step.get("area"):
                self.granted.add(step["area"])
                self.requested.add(step["area"])
            if step.get("door") and node in ahead and step["door"] not in self.doors:
                self._open_door(step["door"])
        if self.restored_pause is not None and state.get("paused"):
            # The last master paused it before a door (in a cabin): still its own pause,
            # let go on once that is open for this master (``_guard_base``), unlike staff's.
            log.warning("%s: paused by the last master for %s %s", self.name, *self.restored_pause)
            self.paused_for = self.restored_pause
            self.paused_at = asyncio.get_running_loop().time()
        self.restored_pause = None
        log.warning(
            "%s: resumes task %s on the vehicle's order %s (update %s, at %s)",
            self.name,
            task_id,
            order_id,
            state.get("orderUpdateId"),
            state["lastNodeId"],
        )
        self.task_id = task_id
        self._start(task_id, self._run(task_id, net, params, resume=state))

    def _resumed_point(
        self, task_id: str, points: list[dict[str, Any]], state: dict[str, Any]
    ) -> int:
        """The tour point a resumed vehicle is at: the last whose stop action it knows, or the
        one after when that action is over; else the first."""
        statuses = {a["actionId"]: a["actionStatus"] for a in state.get("actionStates", [])}
        at = 0
        for i, point in enumerate(points):
            for kind in ("speak", "wait"):
                status = statuses.get(f"{task_id}-{kind}-{point['index']}")
                if status is not None:
                    at = i + 1 if status in DONE_ACTIONS else i
        return at

    async def _take_over(self) -> None:
        """A vehicle still on an order this master did not give (before a restart of the
        server, or from another master) is stopped with ``cancelOrder`` first: it would refuse
        a new order while that one runs."""
        state = self.state or {}
        if not state.get("nodeStates") or state.get("orderId") == self.order_id:
            return
        log.warning(
            "%s: the vehicle still runs order %s: cancelled before the task",
            self.name,
            state["orderId"],
        )
        await self.instant("cancelOrder")
        loop = asyncio.get_running_loop()
        deadline = loop.time() + ACK_TIMEOUT_S * ORDER_TRIES
        while (self.state or {}).get("nodeStates") or (self.state or {}).get("driving"):
            if loop.time() > deadline:
                raise DriveFailed(f"{self.name} did not cancel its order {state['orderId']}")
            self.changed.clear()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(0.5):
                    await self.changed.wait()

    async def _visit(
        self,
        task_id: str,
        point: Mapping[str, Any],
        lang: str,
        resume: dict[str, Any] | None = None,
    ) -> None:
        """One tour stop: drive there, explain it with a ``speak`` node action."""
        index, total = int(point["index"]), int(point["total"])
        text = str(point.get("text") or point.get("name") or "")
        if self.speaks:
            parameters: list[dict[str, Any]] = [
                {"key": "text", "value": text},
                {"key": "lang", "value": str(point.get("lang") or lang)},
            ]
            kind = "speak"
        else:
            parameters = [{"key": "seconds", "value": speak_seconds(text)}]
            kind = "wait"
        action = {
            "actionId": f"{task_id}-{kind}-{index}",
            "actionType": kind,
            "blockingType": "HARD",
            "actionParameters": parameters,
        }

        def arrived() -> None:
            self.ep.publish(
                TourProgress(
                    task_id=task_id,
                    robot=self.name,
                    index=index,
                    total=total,
                    poi=point.get("poi"),
                    stage="arrived",
                )
            )

        await self.drive(task_id, str(point["node"]), [action], on_arrival=arrived, resume=resume)
        self.ep.publish(
            TourProgress(
                task_id=task_id,
                robot=self.name,
                index=index,
                total=total,
                poi=point.get("poi"),
                stage="explained",
            )
        )

    # -- driving ---------------------------------------------------------------------------
    async def drive(
        self,
        task_id: str,
        goal: str,
        actions: list[dict[str, Any]] | None = None,
        *,
        on_arrival: Callable[[], None] | None = None,
        resume: dict[str, Any] | None = None,
    ) -> None:
        """Bring the vehicle to ``goal``: one order per floor of the path (a leg), its base
        released as far as the areas granted, the doors open and the cabin at the landing
        allow, extended by an update at each grant, opening or arrival; between two legs an
        elevator ride. The ``actions`` run at the goal. ``resume``: the vehicle's state, whose
        order to ``goal`` (given by an earlier master control) is extended rather than a new
        one sent. Raises DriveFailed with the reason."""
        for replans in range(REPLANS + 1):
            try:
                await self._drive(task_id, goal, actions, on_arrival, resume)
                return
            except OrderLost as exc:
                here = self._where()
                log.warning(
                    "%s: the vehicle no longer runs order %s: planned again from %s (%d)",
                    self.name,
                    exc,
                    here,
                    replans + 1,
                )
                resume = None
                await self._take_over()  # on another order: stopped first, or it refuses ours
        raise DriveFailed(f"{self.name} lost its order {REPLANS + 1} times on the way to {goal}")

    def _where(self) -> str | None:
        """Where the vehicle's state says it is (its ``lastNodeId``, when a node of the
        site): a drive planned again starts there, whatever the master last thought (a
        new order from another node is refused: "not at <node>")."""
        last = str((self.state or {}).get("lastNodeId") or "")
        if last in self.nodes and last != self.node:
            log.info("%s: the vehicle says it is at %s, not %s", self.name, last, self.node)
            self.node, self.floor, self.placed = last, self.nodes[last].floor, None
        return self.node

    async def _drive(
        self,
        task_id: str,
        goal: str,
        actions: list[dict[str, Any]] | None,
        on_arrival: Callable[[], None] | None,
        resume: dict[str, Any] | None,
    ) -> None:
        """``drive`` once: OrderLost when the vehicle drops the order on the way."""
        resumed = await self._resumed_path(goal, resume) if resume is not None else None
        if resumed is not None:
            steps, start, lead = resumed
        else:
            steps, start, lead = await self._path(self.node, goal), 0, None
        last = len(steps) - 1
        rides = [
            i
            for i in range(start, last)
            if steps[i].get("elevator")
            and steps[i + 1].get("elevator") == steps[i]["elevator"]
            and steps[i + 1]["floor"] != steps[i]["floor"]
        ]
        starts = [start, *(r + 1 for r in rides)]
        ends = [*rides, last]
        for n, (first, end) in enumerate(zip(starts, ends, strict=True)):
            if n:
                await self._ride(steps[first - 1], steps[first])
            final = end == last
            await self._leg(
                task_id,
                steps[: end + 1],
                first,
                actions if final else None,
                on_arrival if final else None,
                lead if n == 0 else None,
            )

    async def _path(self, start: str | None, goal: str) -> list[dict[str, Any]]:
        """The Traffic Manager's path from ``start`` to ``goal`` (its steps)."""
        try:
            reply = await self.ep.request(
                GetPath(robot=self.name, from_node=start, to_node=goal), timeout=5.0
            )
        except RequestTimeout:
            raise DriveFailed(f"no path to {goal}: the Traffic Manager did not answer") from None
        steps: list[dict[str, Any]] = reply.payload.get("steps") or []
        if reply.type != "path" or not steps:
            raise DriveFailed(f"no path to {goal}: {reply.payload.get('error', 'none')}")
        return steps

    async def _resumed_path(
        self, goal: str, state: dict[str, Any]
    ) -> tuple[list[dict[str, Any]], int, tuple[str, int, int]] | None:
        """When the vehicle's order (in ``state``) goes to ``goal``: the steps indexed as its
        sequence ids (step i is node sequence id 2 i; the steps it has passed are empty), the
        step it stands at, and (order id, update id, the step its base ends at) to extend it;
        the path after the base is the Traffic Manager's. None: that order goes elsewhere."""
        nodes = sorted(state.get("nodeStates", []), key=lambda n: int(n["sequenceId"]))
        here, seq = str(state["lastNodeId"]), int(state["lastNodeSequenceId"])
        if (str(nodes[-1]["nodeId"]) if nodes else here) != goal or self.step_of is None:
            return None
        chain = [here] + [str(n["nodeId"]) for n in nodes if n["released"]]
        if not all(node in self.nodes for node in chain):
            return None
        start = step_of_seq(seq)
        base_end = start + len(chain) - 1
        after = await self._path(chain[-1], goal)
        steps: list[dict[str, Any]] = [{} for _ in range(start)]
        steps += [self.step_of(node) for node in chain[:-1]] + after
        self.node = here
        return steps, start, (str(state["orderId"]), int(state["orderUpdateId"]), base_end)

    async def _ride(self, cabin: Mapping[str, Any], exit_: Mapping[str, Any]) -> None:
        """The vehicle stands in the cabin: call it to the exit's floor, and once it is there
        with its door open tell the vehicle where it is now (``initPosition`` on that floor's
        map): the next leg is a new order there."""
        elevator, floor = str(cabin["elevator"]), str(exit_["floor"])
        self.waiting = "riding"
        while self.cabins.get(elevator) != (floor, True):
            self.changed.clear()
            self._call(elevator, floor)
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(0.5):
                    await self.changed.wait()
        self.node, self.floor = str(exit_["node"]), floor
        self.ep.publish(NodeReached(robot=self.name, node=self.node, floor=floor))
        map_id = self.map_ids.get(floor, floor)
        self.placed = self.node
        await self.instant("initPosition", parameters=init_position(exit_, map_id))

    async def _leg(
        self,
        task_id: str,
        steps: list[dict[str, Any]],
        first: int,
        actions: list[dict[str, Any]] | None,
        on_arrival: Callable[[], None] | None,
        lead: tuple[str, int, int] | None = None,
    ) -> None:
        """One order: the vehicle from ``steps[first]`` to the last of ``steps``; ``lead``:
        (order id, update id, the step its base ends at) of the vehicle's order to extend
        (``_resumed_path``) instead of a new one."""
        update, base_end, sent_at, tries = -1, first - 1, -math.inf, 0
        taken = lead is not None  # the vehicle has had this order (then losing it is news)
        if lead is None:
            order_id = self.order_id = self._new_order_id(task_id)
        else:
            order_id, update, base_end = lead
            self.order_id = order_id
            tries, sent_at = 1, asyncio.get_running_loop().time()
        last = len(steps) - 1
        self.route = {node_seq(i): str(steps[i]["node"]) for i in range(first + 1, len(steps))}
        self.route_seq = node_seq(first)
        action_ids = {a["actionId"] for a in actions or []}
        order: dict[str, Any] = {}
        arrived = False
        loop = asyncio.get_running_loop()
        while True:
            self.changed.clear()  # news during this turn (its awaits too) ends the wait below
            state = self.state or {}
            ours = state.get("orderId") == order_id
            progress = step_of_seq(state["lastNodeSequenceId"]) if ours else first
            self._release_behind(steps, progress)
            released_to = self._releasable(steps, progress)
            await self._guard_base(steps, progress, base_end)
            if released_to > base_end:
                update += 1
                order = build_order(
                    self.vehicle,
                    self._header_id("order"),
                    order_id,
                    update,
                    steps,
                    start=max(base_end, first),
                    released_to=released_to,
                    map_ids=self.map_ids,
                    actions={last: actions or []} if base_end < last else None,
                )
                base_end, tries, sent_at = released_to, 0, -math.inf  # goes at once
            acked = ours and state.get("orderUpdateId", -1) >= update
            taken = taken or ours
            if taken and not ours and self.online:  # restarted, or lost it while away
                raise OrderLost(order_id)
            if not acked and self.online and loop.time() - sent_at > ACK_TIMEOUT_S:
                if tries >= ORDER_TRIES:
                    raise DriveFailed(
                        f"{self.name} never acknowledged order {order_id} "
                        f"(update {update}, sent {tries} times)"
                    )
                heard = self.heard  # before the send: a state meanwhile may not have heard it
                if await self.send("order", order):
                    sent_at = loop.time()
                    if heard:  # one the vehicle could not hear is no try
                        tries += 1
            refusal = self._refusal(order_id)
            if refusal is not None:
                raise DriveFailed(f"{self.name} refused the order: {refusal}")
            cabin = steps[progress].get("elevator")
            if cabin and progress < last:  # getting out: keep the cabin's door open
                self._call(cabin, str(steps[progress]["floor"]))
            if acked and progress == last:
                if not arrived and on_arrival is not None:
                    on_arrival()
                arrived = True
                done = {
                    a["actionId"]
                    for a in state.get("actionStates", [])
                    if a["actionStatus"] in DONE_ACTIONS
                }
                if not state.get("driving") and action_ids <= done:
                    return
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(0.5):
                    await self.changed.wait()

    def _new_order_id(self, task_id: str) -> str:
        """``<task id>-<n>``, n after any order of this task the vehicle last had (from an
        earlier master control): an order id is never given twice."""
        last = _order_number(str((self.state or {}).get("orderId") or ""))
        if last is not None and last[0] == task_id:
            self._orders = max(self._orders, last[1])
        self._orders += 1
        return f"{task_id}-{self._orders}"

    def _refusal(self, order_id: str) -> str | None:
        """The vehicle's error that names this order, if any (its description)."""
        for error in (self.state or {}).get("errors", []):
            for ref in error.get("errorReferences") or []:
                if ref.get("referenceKey") == "orderId" and ref.get("referenceValue") == order_id:
                    return str(error.get("errorDescription") or error["errorType"])
        return None

    def _releasable(self, steps: list[dict[str, Any]], progress: int) -> int:
        """The last step the vehicle may be released to: before the next area not granted or
        the next door not open (asking for them on the way), or the cabin it stands in while
        that is not open at its floor (calling it there)."""
        self.waiting = None
        if self._getting_out(steps, progress):  # out of a cabin only while it stands open here
            cabin, floor = str(steps[progress]["elevator"]), str(steps[progress]["floor"])
            if self.cabins.get(cabin) != (floor, True):
                self._call(cabin, floor)
                self.waiting = "waiting_elevator"
                return progress
        for i in range(progress + 1, len(steps)):
            area = steps[i].get("area")
            if area and area != steps[i - 1].get("area") and area not in self.granted:
                if area not in self.requested:
                    self.requested.add(area)
                    self.ep.publish(RequestArea(robot=self.name, area=area))
                self.waiting = "waiting_area"
                return i - 1
            door = steps[i].get("door")
            if door and not self._passable(door):
                self.waiting = "waiting_door"
                return i - 1
            elevator = steps[i].get("elevator")
            if elevator and steps[i - 1].get("elevator") != elevator:  # into the cabin
                floor = str(steps[i]["floor"])
                self._call(elevator, floor)
                if self.cabins.get(elevator) != (floor, True):
                    self.waiting = "waiting_elevator"
                    return i - 1
        return len(steps) - 1

    async def _guard_base(self, steps: list[dict[str, Any]], progress: int, base_end: int) -> None:
        """Something on the released base ahead that is no longer open for the vehicle
        (``_closed_ahead``: the building closed it under its hold: staff, its own timer) pauses
        it (``startPause``: a released base cannot be taken back) while it is asked for again
        (``_passable``, the keep-open call of ``_leg``); once it is open again, ``stopPause``.
        A pause the vehicle's state does not show is sent again after ``ACK_TIMEOUT_S``."""
        closed = self._closed_ahead(steps, progress, base_end)
        now = asyncio.get_running_loop().time()
        if closed is not None:
            self.waiting = f"waiting_{closed[0]}"
            shown = (self.state or {}).get("paused")
            if self.paused_for is None or (not shown and now - self.paused_at > ACK_TIMEOUT_S):
                if self.paused_for is None:
                    log.warning(
                        "%s: %s %s closed before the vehicle passed it: paused until it is "
                        "open again",
                        self.name,
                        *closed,
                    )
                self._pause_for(closed)
                self.paused_at = now
                await self.instant("startPause")
            self._pause_for(closed)
        elif self.paused_for is not None:
            log.info("%s: %s %s open again: goes on", self.name, *self.paused_for)
            self._pause_for(None)
            if not self.staff_paused:
                await self.instant("stopPause")

    def _pause_for(self, device: tuple[str, str] | None) -> None:
        """The master's own pause is for ``device`` now (None: over), kept in the event log
        on every change: a new master control (fail-over, restart) reads it back and lets the
        vehicle go on once that device is open, where it took the pause for staff's."""
        if device == self.paused_for:
            return
        self.paused_for = device
        if self.record is not None:
            where = {"for": device[0], "id": device[1]} if device is not None else {}
            self.record(PAUSE_EVENT, {"robot": self.name, "paused": device is not None, **where})

    def _closed_ahead(
        self, steps: list[dict[str, Any]], progress: int, base_end: int
    ) -> tuple[str, str] | None:
        """("elevator", id) when the vehicle stands in a cabin it is released to get out of and
        the cabin is no longer open at its floor; ("door", id) for a door on the released base
        ahead (its node not reached yet: one already reached is driven through) that is no
        longer held open for it; else None."""
        if base_end > progress and self._getting_out(steps, progress):
            cabin, floor = str(steps[progress]["elevator"]), str(steps[progress]["floor"])
            if self.cabins.get(cabin) != (floor, True):
                return ("elevator", cabin)
        for i in range(progress + 1, min(base_end, len(steps) - 1) + 1):
            door = steps[i].get("door")
            if door and not self._passable(str(door)):
                return ("door", str(door))
        return None

    @staticmethod
    def _getting_out(steps: list[dict[str, Any]], progress: int) -> bool:
        """The vehicle stands in a cabin and its next step is out of it."""
        cabin = steps[progress].get("elevator")
        return (
            bool(cabin)
            and progress + 1 < len(steps)
            and steps[progress + 1].get("elevator") != cabin
        )

    def _release_behind(self, steps: list[dict[str, Any]], progress: int) -> None:
        """Give back the areas left and the doors passed."""
        here = steps[progress].get("area")
        passed_areas = {s.get("area") for s in steps[: progress + 1]}
        for area in sorted(self.granted):
            if area != here and area in passed_areas:
                self._release_area(area)
        passed_doors = {s.get("door") for s in steps[:progress]}
        for door in sorted(self.doors & passed_doors):
            self._forget_door(door)
            self.ep.publish(ReleaseDoor(door=door))

    def _left(self, before: str | None, now: str) -> None:
        """The areas the vehicle has just left are released before its ``node_reached``, as
        a robot does (the Traffic Manager may give them on at once)."""
        for area in sorted(self.granted):
            nodes = self.area_nodes.get(area, frozenset())
            if before in nodes and now not in nodes:
                self._release_area(area)

    def _release_area(self, area: str) -> None:
        self.kept.pop(area, None)
        self._confirmed.discard(area)
        self.granted.discard(area)
        self.requested.discard(area)
        self.ep.publish(ReleaseArea(robot=self.name, area=area))

    def _release_all(self) -> None:
        """At a task's end: every door, every area but those the vehicle may be inside (its
        last node's and its next node's: cancelled on the edge, it may stand in the next
        area, or drive on into it until it stops), kept until a state shows it out of them
        (issue 36's rule for GuideBot robots: backend/traffic/whereabouts.py)."""
        for door in sorted(self.doors):
            self._forget_door(door)
            self.ep.publish(ReleaseDoor(door=door))
        near = self._may_be_in()
        for area in sorted(self.granted | self.requested):
            if area in near:
                self.kept[area] = self.node
            else:
                self._release_area(area)

    def _may_be_in(self) -> set[str]:
        """The areas the vehicle may be inside: its last node's and, on an order, the next
        node's of its route."""
        nodes = [self.node]
        ahead = [s for s in self.route if s > self.route_seq]
        if ahead:
            nodes.append(self.route[min(ahead)])
        return {a for a, members in self.area_nodes.items() if any(n in members for n in nodes)}

    def _release_kept(self, state: Mapping[str, Any]) -> None:
        """Areas kept at a task's end: one on the route of the task now running is its own
        again; one the vehicle is seen out of goes (``_out_of``)."""
        on_route = {
            a
            for a, members in self.area_nodes.items()
            if self.task_id is not None and any(n in members for n in self.route.values())
        }
        for area, then in sorted(self.kept.items()):
            if area in on_route:
                del self.kept[area]
            elif self._out_of(area, then, state):
                del self.kept[area]
                if area in self.granted | self.requested:
                    log.info(
                        "%s: out of area %s (kept at its task's end): released", self.name, area
                    )
                    self._release_area(area)

    def _out_of(self, area: str, then: str | None, state: Mapping[str, Any]) -> bool:
        """Whether ``state`` shows the vehicle out of ``area``: its last node not in it and
        its position outside the area's extent (``area_boxes``), while it stands, or drives
        an order of ours that does not go there. Without a position: once it has reached
        another node outside the area."""
        if self._stands_in(area, self.node):
            return False
        position = _position(state)
        if position is None:
            return self.node != then
        if state.get("driving") and self.task_id is None:
            return False  # still stopping after a cancel: it may drive on into the area
        floor = self.floor_of_map.get(str(position["mapId"]))
        box = self.boxes.get((area, floor)) if floor is not None else None
        return box is None or not inside(box, float(position["x"]), float(position["y"]))

    def _stands_in(self, area: str, node: str | None) -> bool:
        return node is not None and node in self.area_nodes.get(area, ())

    def _on_area_granted(self, msg: Message, granted: AreaGranted) -> None:
        if granted.robot != self.name:
            return
        area = granted.area
        if granted.removed:
            log.info("%s: area %s removed: %s", self.name, area, granted.reason)
        if area in self.requested:
            self.granted.add(area)
        for rid, asked in self.zone_requests.items():
            if asked != area:
                continue
            if not granted.removed:
                self._answer(rid, "GRANTED")
            else:  # the area is gone from the site: a grant is taken back, a wait refused
                self._answer(rid, "REVOKED" if self._answered.get(rid) == "GRANTED" else "REJECTED")
        self.changed.set()

    def _on_cabin(self, msg: Message, cabin: ElevatorInPosition) -> None:
        self.cabins[cabin.elevator] = (cabin.floor, cabin.door_open)
        self.changed.set()

    def _call(self, elevator: str, floor: str) -> None:
        """Call the cabin to ``floor``, again only after ``recall_s``."""
        now = asyncio.get_running_loop().time()
        if now - self._called.get((elevator, floor), -math.inf) >= self.recall_s:
            self._called[(elevator, floor)] = now
            self.ep.publish(CallElevator(elevator=elevator, floor=floor))

    def _open_door(self, door: str) -> None:
        """Ask the building to open ``door`` and hold it open for this vehicle."""
        self.doors.add(door)
        message = self.ep.publish(OpenDoor(door=door))
        self.door_asks[door] = (message.id, asyncio.get_running_loop().time())

    def _forget_door(self, door: str) -> None:
        self.doors.discard(door)
        self.held_doors.discard(door)
        self.door_asks.pop(door, None)

    def _passable(self, door: str) -> bool:
        """``door`` is open and held for this vehicle (asked for now if not yet; asked again
        every ``DOOR_ASK_S`` while the building has not answered: a refusal is not heard)."""
        if door not in self.doors:
            self._open_door(door)
        elif door not in self.held_doors:
            _, sent = self.door_asks.get(door, ("", -math.inf))
            if asyncio.get_running_loop().time() - sent >= DOOR_ASK_S:
                self._open_door(door)
        return door in self.held_doors and door in self.open_doors

    def _on_door(self, msg: Message, answer: DoorOpened | DoorClosed) -> None:
        door = answer.door
        if msg.type == "door_opened":
            self.open_doors.add(door)
            ask = self.door_asks.get(door)
            if ask is not None and msg.correlation_id == ask[0] and door in self.doors:
                self.held_doors.add(door)  # the building's answer to our open_door
                del self.door_asks[door]
        else:  # closed under our hold too (staff, the hold ran out): asked again
            self.open_doors.discard(door)
            self.held_doors.discard(door)
        self.changed.set()


def _order_number(order_id: str) -> tuple[str, int] | None:
    """(task id, n) of an order id ``<task id>-<n>`` the master gives; None for another."""
    task_id, dash, n = order_id.rpartition("-")
    return (task_id, int(n)) if dash and task_id and n.isdigit() else None


def _position(state: Mapping[str, Any]) -> dict[str, Any] | None:
    """The vehicle's pose: ``agvPosition`` (2.x) or ``mobileRobotPosition`` (3.x)."""
    found = state.get("agvPosition") or state.get("mobileRobotPosition")
    return dict(found) if found else None


def _battery(state: Mapping[str, Any]) -> tuple[float, bool]:
    """(charge in %, charging): ``batteryState`` (2.x) or ``powerSupply`` (3.x); 100 % and
    not charging before a state says."""
    b = state.get("batteryState") or state.get("powerSupply") or {}
    return float(b.get("batteryCharge", b.get("stateOfCharge", 100.0))), bool(b.get("charging"))
