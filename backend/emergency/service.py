"""EmergencyService: the fire alarm's state on the server, and what it holds (docs/emergency.md).

It hears the site's alarm inputs (``building_input_changed`` of role ``fire_alarm`` points)
and the people who declare or resume by REST; while an alarm holds a zone it refuses new task
requests (TaskManager.hold), keeps the robots of the zone out of the queue, cuts off their
tasks (back to the queue in their place, run again on resume), sends each of them ``evacuate``
with its way to the nearest safe spot, refuses doors and elevators of the zone
(BuildingInterface.gate) and drops the doors' holders. Its state is replayed from the event log
on start, so a restart during an alarm keeps the alarm.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Callable, Collection
from typing import Any, Protocol

from backend.emergency.state import (
    TRANSITIONS,
    EmergencyError,
    EmergencyState,
    IllegalMove,
    ResumeRefused,
)
from backend.tasks.manager import TaskManager
from backend.tasks.robots import RobotInfo
from guidebot.delivery import courier_for, listen
from guidebot.messages import Message, make_message
from guidebot.payloads.building import BuildingInputChanged
from guidebot.payloads.emergency import (
    EmergencyChanged,
    Evacuate,
    EvacuationState,
    LandingWay,
)
from guidebot.payloads.robot import RobotState
from guidebot.payloads.tasks import RobotLink
from guidebot.service import Service
from guidebot.site.building import Elevator
from guidebot.site.emergency import (
    Alarm,
    AlarmZone,
    Emergency,
    SafetyTable,
    nearest_safe_spot,
    safety_table,
    zone_nodes,
)
from guidebot.site.schema import Site
from guidebot.site.steps import PathStep

__all__ = ["EmergencyService"]

log = logging.getLogger(__name__)

CUT_OFF_REASON = "fire alarm"
INPUT_WAIT_S = 0.05
"""How often the start-up check looks for the alarm inputs' first values (they are no event)."""


class EventStore(Protocol):
    def record_event(self, kind: str, source: str, data: dict[str, Any]) -> None: ...

    async def events(
        self, *, after_id: int = 0, limit: int = 100, kind: str | None = None, latest: bool = False
    ) -> list[dict[str, Any]]: ...


class BuildingView(Protocol):
    values: dict[tuple[str, str], int]

    def drop_door_holders(self, nodes: set[str], evacuating: Collection[str] = ()) -> list[str]: ...


class EmergencyService(Service):
    """One per server (backend.emergency.component on ``app.state.emergency``)."""

    def __init__(
        self,
        endpoint: Any,
        site: Callable[[], Site],
        tasks: TaskManager,
        store: EventStore,
        building: Callable[[], BuildingView | None],
    ) -> None:
        super().__init__()
        self.endpoint = endpoint
        self._site = site
        self.tasks = tasks
        self.store = store
        self._building = building
        self.state = EmergencyState.normal
        self.zones: list[AlarmZone] = []
        self.since: float | None = None
        self.declared_by = ""
        self.reason = ""
        self.cut_off: list[str] = []
        """Tasks cut off by the alarm: back in the queue at their place, run again on resume."""
        self.evacuation: dict[str, dict[str, Any]] = {}
        """Robot -> its evacuation: safe_spot, path, state (ordered, stopped, moving, safe,
        stuck), node, why, at."""
        self._held: tuple[int, frozenset[str]] = (0, frozenset())
        self._told: dict[str, object] = {}
        """Robot -> the boot id of its agent process that was told of this alarm: a robot
        that connects, or whose agent restarts, during the alarm hears of it at once."""
        self._near_cabins: tuple[Site | None, dict[str, list[Elevator]]] = (None, {})
        """Node -> the elevators whose cabin a robot there may be in (per site, built once)."""
        self._safety: tuple[Site | None, SafetyTable] = (None, {})
        """Every node's way to its nearest safe spot, per site (one search, not one a robot:
        on a 3000-node site 20 searches took 0.9-4 s between the alarm and the last order)."""
        self.courier = courier_for(endpoint)
        """evacuate: sent again until the robot's link acknowledges it."""

    # -- life cycle ------------------------------------------------------------------------

    async def restore(self) -> None:
        """The state the last server life ended in, replayed from the event log."""
        declared = await self.store.events(kind="emergency_declared", latest=True, limit=1)
        resumed = await self.store.events(kind="emergency_resumed", latest=True, limit=1)
        if not declared or (resumed and resumed[-1]["id"] > declared[-1]["id"]):
            return
        data = declared[-1]["data"]
        self.state = EmergencyState.alarm
        self.zones = [AlarmZone.model_validate(z) for z in data.get("zones", [{}])]
        self.since = data.get("since")
        self.declared_by = data.get("by", "")
        self.reason = data.get("reason", "")
        self.cut_off = list(data.get("cut_off", []))
        log.warning("fire alarm restored from the event log: %s", self.reason)

    async def on_start(self) -> None:
        ep = self.endpoint
        self.on(ep, BuildingInputChanged, self._on_input)
        self.on(ep, EvacuationState, self._on_evacuation_state)
        self.on(ep, RobotState, self._on_robot_state)
        self.on(ep, RobotLink, self._on_robot_gone, types=["robot_disconnected"])
        for unsubscribe in listen(self.endpoint, self.courier):
            self.on_cleanup(unsubscribe)
        self.on_cleanup(self.courier.close)
        self.safety()  # now rather than when the alarm sounds
        self._landings(None)
        self.spawn(self._first_values(), name="emergency-first-values")
        if self.state is not EmergencyState.normal:
            self._publish()

    async def _first_values(self) -> None:
        """A module's first sample is no event: read the alarm inputs once they are known."""
        while True:
            building = self._building()
            alarms = self._alarms()
            if building is None or not alarms:
                return
            if all((a.input.module, a.input.point) in building.values for a in alarms):
                break
            await asyncio.sleep(INPUT_WAIT_S)
        for alarm in alarms:
            if self._reads_alarm(alarm) is True:
                self.declare(alarm.zone, reason=f"alarm input {alarm.id}", by=f"input:{alarm.id}")
        self._maybe_input_clear()

    # -- what the site says ----------------------------------------------------------------

    @property
    def site(self) -> Site:
        return self._site()

    def _emergency(self) -> Emergency:
        return self.site.emergency or Emergency()

    def _alarms(self) -> list[Alarm]:
        return self._emergency().alarms

    def _reads_alarm(self, alarm: Alarm) -> bool | None:
        """True: the input reads alarm; False: normal; None: cannot be read now."""
        building = self._building()
        value = (
            None
            if building is None
            else building.values.get((alarm.input.module, alarm.input.point))
        )
        return None if value is None else int(value) == alarm.active_when

    def safety(self) -> SafetyTable:
        """The site's safety table (cached per site; warmed on start, off the alarm's path)."""
        site = self.site
        if self._safety[0] is not site:
            self._safety = (site, safety_table(site, self._emergency()))
        return self._safety[1]

    def held_nodes(self) -> frozenset[str]:
        """The nodes the alarm holds now (cached per state and site)."""
        key = hash((id(self.site), self.state, tuple(z.model_dump_json() for z in self.zones)))
        if self._held[0] != key:
            nodes: set[str] = set()
            if self.state is not EmergencyState.normal:
                for zone in self.zones:
                    nodes |= zone_nodes(self.site, zone)
            self._held = (key, frozenset(nodes))
        return self._held[1]

    # -- the holds (TaskManager.hold, BuildingInterface.gate) -------------------------------

    def refusal(self, lang: str | None) -> str | None:
        """Why a new task is refused now, in ``lang`` (None: not refused)."""
        if self.state is EmergencyState.normal:
            return None
        return self._emergency().words_in(lang, self.site.default_language)

    def holds(self, robot: RobotInfo) -> bool:
        """The robot is in a held zone (or nobody knows where it is): no task for it."""
        if self.state is EmergencyState.normal:
            return False
        return robot.node is None or robot.node in self.held_nodes()

    def area_refusal(self, robot: str, area: str) -> str | None:
        """TrafficManager.gate: an area of the zone only for a robot whose way to its safe
        spot crosses it (a robot in an escape route leaves it this way)."""
        held = self.held_nodes()
        if not held:
            return None
        nodes = next((set(a.nodes) for a in self.site.areas if a.id == area), set())
        if not nodes & held:
            return None
        entry = self.evacuation.get(robot, {})
        ways = [entry.get("path", []), *_landing_paths(entry)]
        if any(nodes & set(way) for way in ways):
            return None
        return f"fire alarm: area {area} is closed to robots not on their way to a safe spot"

    def building_refusal(self, node: str) -> str | None:
        if node in self.held_nodes():
            return f"fire alarm: no door opened or elevator called in the alarm's zone ({node})"
        return None

    # -- moves -----------------------------------------------------------------------------

    def _move(self, new: EmergencyState) -> None:
        if new not in TRANSITIONS[self.state]:
            raise IllegalMove(self.state, new)
        self.state = new

    def check_zone(self, zone: AlarmZone) -> None:
        """Raise EmergencyError naming the floors or areas the site does not have."""
        floors = {f.id for f in self.site.floors}
        areas = {a.id for a in self.site.areas}
        if bad := [f for f in zone.floors if f not in floors]:
            raise EmergencyError(
                f"unknown floor(s) {', '.join(bad)}"
                f" (the site's floors: {', '.join(sorted(floors))})"
            )
        if bad := [a for a in zone.areas if a not in areas]:
            raise EmergencyError(
                f"unknown area(s) {', '.join(bad)}"
                f" (the site's areas: {', '.join(sorted(areas)) or 'none'})"
            )

    def declare(self, zone: AlarmZone | None, *, reason: str, by: str) -> dict[str, Any]:
        """An alarm holds ``zone`` (None: the whole site) from now on; idempotent per zone."""
        zone = zone or AlarmZone()
        self.check_zone(zone)
        known = {z.model_dump_json() for z in self.zones}
        if self.state is EmergencyState.alarm and zone.model_dump_json() in known:
            return self.snapshot()
        self._move(EmergencyState.alarm)
        if zone.model_dump_json() not in known:
            self.zones.append(zone)
        if self.since is None:
            self.since, self.declared_by, self.reason = time.time(), by, reason
        log.warning("fire alarm (%s) by %s: %s", zone.describe(), by, reason)
        self._hold_robots()
        building = self._building()
        doors = (
            []
            if building is None
            else building.drop_door_holders(set(self.held_nodes()), set(self.evacuation))
        )
        self.store.record_event(
            "emergency_declared",
            "emergency",
            {
                "zones": [z.model_dump() for z in self.zones],
                "zone": zone.model_dump(),
                "since": self.since,
                "by": by,
                "reason": reason,
                "cut_off": self.cut_off,
                "doors_dropped": doors,
            },
        )
        self._publish()
        return self.snapshot()

    def _hold_robots(self) -> None:
        """Cut off the tasks of the robots the alarm holds and send each one to safety."""
        for robot in list(self.tasks.robots.values()):
            if not robot.online or not self.holds(robot) or robot.name in self.evacuation:
                continue
            way = self._way(robot.node)
            landings = self._landings(robot.node)
            order = Evacuate(
                safe_spot=way.safe_spot,
                path=way.path,
                steps=way.steps,
                words=self._words(),
                landings=landings,
            )
            message = make_message(order, source=self.endpoint.name, destination=robot.name)
            self.courier.post(message, key=("evacuate", robot.name))
            # The order first: the robot stops before its task's cancel reaches it.
            task = self.tasks.current_of(robot)
            if task is not None and not task.final:
                if not task.internal:
                    self.cut_off.append(task.id)
                self.tasks.requeue(task, CUT_OFF_REASON)
            self.evacuation[robot.name] = {
                "safe_spot": order.safe_spot,
                "path": order.path,
                "state": "ordered",
                "node": robot.node,
                "why": "" if way.path else "no way to a safe spot without an elevator",
                "at": time.time(),
                **(
                    {
                        "landings": {
                            e: {f: w.path for f, w in ways.items()} for e, ways in landings.items()
                        }
                    }
                    if landings
                    else {}
                ),
            }
            self.store.record_event(
                "robot_evacuation",
                "emergency",
                {"robot": robot.name, "state": "ordered", "safe_spot": order.safe_spot},
            )

    def _way(self, node: str | None) -> LandingWay:
        """The way from ``node`` to its nearest safe spot (none: no way, or nowhere known)."""
        path = (
            nearest_safe_spot(self.site, self._emergency(), node, self.safety()) if node else None
        )
        return LandingWay(
            safe_spot=path[-1] if path else None, path=path or [], steps=self._steps(path or [])
        )

    def _landings(self, node: str | None) -> dict[str, dict[str, LandingWay]]:
        """A robot last seen on a cabin's node, or next to one (it may have got in since its
        last report), may be riding it: the way from each landing of those elevators, by
        elevator and floor (it gets out where the cabin stops, docs/emergency.md)."""
        site = self.site
        if self._near_cabins[0] is not site:
            self._near_cabins = (site, cabins_near(site))
        return {
            elevator.id: {stop.floor: self._way(stop.node) for stop in elevator.stops}
            for elevator in self._near_cabins[1].get(node or "", [])
        }

    def _steps(self, path: list[str]) -> list[dict[str, Any]]:
        nodes = {n.id: n for n in self.site.nodes}
        area_of = {node: a.id for a in self.site.areas for node in a.nodes}
        return [
            PathStep(n.id, n.floor, n.x, n.y, area=area_of.get(n.id)).as_dict()
            for n in (nodes[node] for node in path)
        ]

    def _words(self) -> dict[str, str]:
        """The site's words, its default language first (a robot without a visitor's
        language says the first)."""
        words = self._emergency().words
        default = self.site.default_language
        return {**({default: words[default]} if default in words else {}), **words}

    def resume(self, *, by: str) -> dict[str, Any]:
        """Back to service (operator or admin); refused while an alarm input reads alarm."""
        if self.state is EmergencyState.normal:
            raise IllegalMove(self.state, EmergencyState.normal)
        for alarm in self._alarms():
            reads = self._reads_alarm(alarm)
            where = f"{alarm.input.module}/{alarm.input.point}"
            if reads is True:
                raise ResumeRefused(
                    f"alarm input {alarm.id} ({where}) still reads alarm: resume once the"
                    " building's alarm is reset"
                )
            if reads is None:
                raise ResumeRefused(
                    f"alarm input {alarm.id} ({where}) cannot be read (building interface or"
                    " module down): resume once it reads normal"
                )
        self._move(EmergencyState.normal)
        cut_off = self.cut_off
        self.store.record_event(
            "emergency_resumed",
            "emergency",
            {"by": by, "since": self.since, "cut_off": cut_off, "zones": self._zone_dicts()},
        )
        log.warning("service resumed by %s after the fire alarm", by)
        self.zones, self.since, self.declared_by, self.reason = [], None, "", ""
        self.cut_off, self.evacuation, self._told = [], {}, {}
        self._publish()
        self.tasks.dispatch()  # the held queue runs, cut-off tasks first in their places
        return {**self.snapshot(), "resumed_tasks": cut_off}

    # -- messages --------------------------------------------------------------------------

    def _on_input(self, msg: Message, changed: BuildingInputChanged) -> None:
        module, point = changed.module, changed.point
        for alarm in self._alarms():
            if (alarm.input.module, alarm.input.point) != (module, point):
                continue
            if int(changed.value) == alarm.active_when:
                self.declare(alarm.zone, reason=f"alarm input {alarm.id}", by=f"input:{alarm.id}")
            else:
                self._maybe_input_clear()

    def _maybe_input_clear(self) -> None:
        """Every alarm input reads normal again: wait for a person (two-step resume)."""
        if self.state is not EmergencyState.alarm or not self.declared_by.startswith("input:"):
            return
        if any(self._reads_alarm(a) is not False for a in self._alarms()):
            return
        self._move(EmergencyState.input_clear)
        self.store.record_event("emergency_input_clear", "emergency", {"zones": self._zone_dicts()})
        self._publish()

    def _on_robot_state(self, msg: Message, state: RobotState) -> None:
        """A robot connecting, or driving into the zone, while the alarm lasts is held too."""
        if self.state is EmergencyState.normal:
            return
        self._tell_new_process(msg.source, state.boot_id)
        if msg.source in self.evacuation:
            return
        robot = self.tasks.robots.get(msg.source)
        if robot is not None and robot.online and self.holds(robot):
            self._hold_robots()

    def _tell_new_process(self, robot: str, boot_id: object) -> None:
        """The alarm's state, sent to an agent process that has not heard it (the broadcast
        went out before it connected: its screen would offer tours the server refuses). A
        restarted agent also forgot its evacuation order: it is ordered again from where it
        stands."""
        if robot in self._told and self._told[robot] == boot_id:
            return
        restarted = robot in self._told
        self._told[robot] = boot_id
        self.endpoint.send(
            make_message(self._changed(), source=self.endpoint.name, destination=robot)
        )
        if restarted and robot in self.evacuation:
            log.warning("%s restarted during the fire alarm: ordered to safety again", robot)
            del self.evacuation[robot]

    def _on_robot_gone(self, msg: Message, link: RobotLink) -> None:
        """Gone before it acted on its order (the courier forgets it): ordered again when it
        reports from the zone."""
        if self.evacuation.get(link.robot, {}).get("state") == "ordered":
            del self.evacuation[link.robot]

    def _on_evacuation_state(self, msg: Message, report: EvacuationState) -> None:
        entry = self.evacuation.setdefault(msg.source, {"safe_spot": None, "path": []})
        entry.update(state=report.state, node=report.node, why=report.why, at=time.time())
        for way in _landing_paths(entry):
            if way and report.node == way[0] and way != entry["path"]:
                # It got out of the cabin at this landing: its way is this landing's.
                entry.update(safe_spot=way[-1], path=way)
        self.store.record_event(
            "robot_evacuation",
            msg.source,
            {
                "robot": msg.source,
                "state": report.state,
                "node": report.node,
                "why": report.why,
                **({"stopped_at": report.stopped_at} if report.stopped_at is not None else {}),
            },
        )

    def _zone_dicts(self) -> list[dict[str, list[str]]]:
        return [z.model_dump(exclude_defaults=True) for z in self.zones]

    def _changed(self) -> EmergencyChanged:
        return EmergencyChanged(
            state=self.state.value,
            zones=self._zone_dicts(),
            since=self.since,
            declared_by=self.declared_by,
            reason=self.reason,
            words=self._emergency().words,
        )

    def _publish(self) -> None:
        self.endpoint.publish(self._changed())

    def snapshot(self) -> dict[str, Any]:
        """What ``GET /api/emergency`` answers."""
        return {
            "state": self.state.value,
            "zones": self._zone_dicts(),
            "since": self.since,
            "declared_by": self.declared_by,
            "reason": self.reason,
            "words": self._emergency().words,
            "cut_off_tasks": list(self.cut_off),
            "robots": {name: dict(entry) for name, entry in sorted(self.evacuation.items())},
            "alarms": [
                {
                    "id": a.id,
                    "module": a.input.module,
                    "point": a.input.point,
                    "reads_alarm": self._reads_alarm(a),
                }
                for a in self._alarms()
            ],
        }


def cabins_near(site: Site) -> dict[str, list[Elevator]]:
    """Node -> the elevators with a cabin's node at it or one edge away."""
    near: dict[str, list[Elevator]] = {}
    stops = {stop.node: elevator for elevator in site.elevators for stop in elevator.stops}
    for node, elevator in stops.items():
        near.setdefault(node, []).append(elevator)
    for edge in site.edges:
        for a, b in ((edge.a, edge.b), (edge.b, edge.a)):
            lift = stops.get(b)
            if lift is not None and a not in stops and lift not in near.get(a, []):
                near.setdefault(a, []).append(lift)
    return near


def _landing_paths(entry: dict[str, Any]) -> list[list[str]]:
    """Every landing's way in a robot's evacuation record."""
    return [path for ways in entry.get("landings", {}).values() for path in ways.values()]
