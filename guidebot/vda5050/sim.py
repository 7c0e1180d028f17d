"""``guidebot vda5050-sim``: a simulated VDA 5050 vehicle (2.1.0, or 3.0.0 when its
``Vehicle`` says so) for tests and the demo.

It drives the released base of its order from node to node in straight lines at its speed
(times ``time_scale``), reports ``state`` every ``state_period_s`` (wall time) and at once on
every event (an order taken or refused, a node reached, an action's state, a pause), honours
the instant actions cancelOrder, startPause, stopPause, startCharging, stopCharging,
initPosition (after an elevator ride) and stateRequest, and says ONLINE on ``connection``
with CONNECTIONBROKEN (3.0.0: CONNECTION_BROKEN) as its last will.
A node action ``speak`` (text, lang) or ``wait`` (seconds) blocks for its time at that node.
3.0.0 (docs/vda5050.md, "The simulated vehicle"): its state's 3.0.0 fields, its zone sets
(``zoneSet``, ``enableZoneSet``), an ACCESS zone request before it drives into an enabled
RELEASE zone (``responses``: it waits for GRANTED, stops with RELEASE_LOST on REVOKED inside),
a BLOCKED zone it does not drive into, SPEED_LIMIT zones, and hibernation (startHibernation,
stopHibernation: connection HIBERNATING, no state meanwhile).
Faults for tests: ``reject_orders`` (the next orders are refused with that reason),
``deaf`` (orders dropped unanswered), ``hung`` (connected, silent and deaf: no last will)
and ``raise_error`` (an error in the state).
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
from dataclasses import dataclass, field
from typing import Any

from guidebot.service import Service
from guidebot.vda5050.mqtt import LastWill, MqttSession
from guidebot.vda5050.schemas import SchemaViolation, check
from guidebot.vda5050.topics import BrokerAddress, Vehicle

__all__ = ["SimVehicle", "speak_seconds"]

log = logging.getLogger(__name__)

TICK_S = 0.05
"""Wall seconds between two steps of the simulated motion."""
V3_INSTANT = ("startHibernation", "stopHibernation", "enableZoneSet")
"""Instant actions a 3.0.0 vehicle offers besides the 2.1.0 ones."""


def inside_polygon(x: float, y: float, vertices: list[dict[str, Any]]) -> bool:
    """Whether (x, y) is inside the polygon (edges count as inside)."""
    points = [(float(v["x"]), float(v["y"])) for v in vertices]
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    if not (min(xs) <= x <= max(xs) and min(ys) <= y <= max(ys)):
        return False
    inside = False
    for (x0, y0), (x1, y1) in zip(points, points[1:] + points[:1], strict=True):
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    if inside:
        return True
    for (x0, y0), (x1, y1) in zip(points, points[1:] + points[:1], strict=True):  # on an edge
        cross = (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)
        if (
            abs(cross) < 1e-9
            and min(x0, x1) <= x <= max(x0, x1)
            and min(y0, y1) <= y <= max(y0, y1)
        ):
            return True
    return False


def speak_seconds(text: str) -> float:
    """How long saying ``text`` takes, in vehicle time (about 15 characters a second)."""
    return max(1.0, len(text) / 15)


@dataclass
class _Action:
    action: dict[str, Any]
    status: str = "WAITING"
    left_s: float = 0.0
    result: str | None = None

    def state(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "actionId": self.action["actionId"],
            "actionType": self.action["actionType"],
            "actionStatus": self.status,
        }
        if self.result is not None:
            out["resultDescription"] = self.result
        return out


@dataclass
class _Order:
    order_id: str = ""
    update_id: int = 0
    nodes: list[dict[str, Any]] = field(default_factory=list)
    """Nodes not yet reached (the first is the next goal), released and horizon."""
    edges: list[dict[str, Any]] = field(default_factory=list)


class SimVehicle(Service):
    """One simulated vehicle on ``broker``; ``x``, ``y``, ``map_id`` and ``node`` its start."""

    def __init__(
        self,
        broker: BrokerAddress,
        vehicle: Vehicle,
        *,
        x: float = 0.0,
        y: float = 0.0,
        map_id: str = "map",
        node: str = "",
        speed: float = 1.0,
        time_scale: float = 1.0,
        state_period_s: float = 1.0,
        battery: float = 1.0,
    ) -> None:
        super().__init__()
        self.vehicle = vehicle
        self.x, self.y, self.theta = x, y, 0.0
        self.map_id = map_id
        self.last_node = node
        self.last_seq = 0
        self.speed = speed
        self.time_scale = time_scale
        self.state_period_s = state_period_s
        self.battery = battery
        self.charging = False
        self.paused = False
        self.driving = False
        self.order = _Order()
        self.actions: dict[str, _Action] = {}
        self.errors: list[dict[str, Any]] = []
        self.reject_orders: str | None = None
        self.speaks = True
        """Whether ``speak`` is among the actions its factsheet offers."""
        self.deaf = False
        """Orders are dropped unanswered (kept in ``orders_ignored``): a vehicle that never
        acknowledges them."""
        self.orders_ignored: list[dict[str, Any]] = []
        self.hung = False
        """Its software hangs: still connected to the broker (so no last will), it says and
        hears nothing until it is let go again."""
        self.orders_received: list[dict[str, Any]] = []
        self.instant_received: list[dict[str, Any]] = []
        self.v3 = vehicle.version.startswith("3.")
        self.instant_actions: dict[str, _Action] = {}
        """3.0.0: instant actions are reported apart (``instantActionStates``)."""
        self.zone_sets: dict[str, dict[str, Any]] = {}
        """3.0.0: zoneSetId -> the zone set, as received."""
        self.enabled: dict[str, str] = {}
        """3.0.0: mapId -> its enabled zoneSetId."""
        self.zone_requests: dict[str, dict[str, Any]] = {}
        """3.0.0: requestId -> the zoneRequest in its state."""
        self.responses_received: list[dict[str, Any]] = []
        self.supported_zones = ["RELEASE", "BLOCKED", "SPEED_LIMIT", "LINE_GUIDED"]
        self.hibernating = False
        self._requests = 0
        self._headers: dict[str, int] = {}
        self._wake = asyncio.Event()
        topics = ["order", "instantActions"] + (["zoneSet", "responses"] if self.v3 else [])
        broken = "CONNECTION_BROKEN" if self.v3 else "CONNECTIONBROKEN"
        self.session = MqttSession(
            broker,
            client_id=f"sim-{vehicle.manufacturer}-{vehicle.serial_number}",
            subscriptions=[vehicle.topic(t) for t in topics],
            on_message=self._on_message,
            on_connect=self._on_connect,
            will=LastWill(vehicle.topic("connection"), self._connection(broken)),
        )

    # -- life cycle ------------------------------------------------------------------------
    async def on_start(self) -> None:
        await self.enter(self.session)
        self.spawn(self._drive(), "vda5050-sim drive")
        self.spawn(self._report(), "vda5050-sim report")

    async def on_stop(self) -> None:
        if self.session.connected.is_set():
            await self._publish("connection", self._connection("OFFLINE"), retain=True)

    def _header(self, topic: str) -> dict[str, Any]:
        self._headers[topic] = self._headers.get(topic, -1) + 1
        return self.vehicle.header(self._headers[topic])

    def _connection(self, state: str) -> dict[str, Any]:
        return {**self.vehicle.header(0), "connectionState": state}

    def _on_connect(self) -> None:
        self.spawn(self._hello(), "vda5050-sim hello")

    async def _hello(self) -> None:
        state = "HIBERNATING" if self.hibernating else "ONLINE"
        await self._say(state)
        if not self.hibernating:
            await self.publish_state()

    async def _say(self, connection: str) -> None:
        message = {**self._header("connection"), "connectionState": connection}
        await self._publish("connection", message, retain=True)

    async def _publish(self, topic: str, message: dict[str, Any], *, retain: bool = False) -> bool:
        if self.hung:
            return False
        return await self.session.publish(self.vehicle.topic(topic), message, retain=retain)

    # -- incoming --------------------------------------------------------------------------
    def _on_message(self, topic: str, payload: bytes) -> None:
        name = topic.rsplit("/", 1)[-1]
        if self.hung:
            return
        try:
            message = json.loads(payload)
            check(name, message, self.vehicle.version)
        except (ValueError, SchemaViolation) as exc:
            self._error("validationError", "WARNING", str(exc)[:500], [])
            return
        if self.hibernating:  # only stopHibernation is heard (6.2.3)
            wake = [a for a in message.get("actions", []) if a["actionType"] == "stopHibernation"]
            if name == "instantActions" and wake:
                self.instant_received.append(message)
                self._instant(wake[0])
            return
        if name == "zoneSet":
            self._take_zone_set(message["zoneSet"])
        elif name == "responses":
            self.responses_received.append(message)
            for response in message["responses"]:
                self._response(response)
        elif name == "order" and self.deaf:
            self.orders_ignored.append(message)
            return
        elif name == "order":
            self.orders_received.append(message)
            self._take_order(message)
        else:
            self.instant_received.append(message)
            for action in message["actions"]:
                self._instant(action)
        self._event()

    def _error(
        self, kind: str, level: str, text: str, refs: list[tuple[str, str]]
    ) -> dict[str, Any]:
        error = {
            "errorType": kind,
            "errorLevel": level,
            "errorDescription": text,
            "errorReferences": [{"referenceKey": k, "referenceValue": v} for k, v in refs],
        }
        self.errors.append(error)
        self._event()
        return error

    def raise_error(self, kind: str, level: str = "WARNING", text: str = "") -> None:
        """An error in the state until ``clear_errors``."""
        self._error(kind, level, text or kind, [])

    def clear_errors(self) -> None:
        self.errors.clear()
        self._event()

    def _take_order(self, order: dict[str, Any]) -> None:
        refs = [("orderId", order["orderId"]), ("orderUpdateId", str(order["orderUpdateId"]))]
        if self.reject_orders is not None:
            self._error("orderError", "WARNING", self.reject_orders, refs)
            return
        same = order["orderId"] == self.order.order_id
        if same and order["orderUpdateId"] <= self.order.update_id:
            if order["orderUpdateId"] < self.order.update_id:
                self._error("orderUpdateError", "WARNING", "an older update of the order", refs)
            return  # the same update again: already taken
        first = order["nodes"][0]
        if same:
            base = [n for n in self.order.nodes if n["released"]]
            stitch = (base[-1]["nodeId"], base[-1]["sequenceId"]) if base else None
            stitch = stitch or (self.last_node, self.last_seq)
            if (first["nodeId"], first["sequenceId"]) != stitch:
                self._error(
                    "orderUpdateError",
                    "WARNING",
                    f"the update starts at {first['nodeId']}, not at the base's end {stitch[0]}",
                    refs,
                )
                return
            self.order.nodes = [*base, *order["nodes"][1:]]
            self.order.edges = [e for e in self.order.edges if e["released"]] + [
                e for e in order["edges"] if e["sequenceId"] > stitch[1]
            ]
            self.order.update_id = order["orderUpdateId"]
        else:
            busy = any(n["released"] for n in self.order.nodes)
            if busy or first["nodeId"] != self.last_node:
                why = "still driving an order" if busy else f"not at {first['nodeId']}"
                self._error("orderError", "WARNING", f"order refused: {why}", refs)
                return
            self.last_seq = first["sequenceId"]
            self.order = _Order(order["orderId"], order["orderUpdateId"], order["nodes"][1:], [])
            self.order.edges = list(order["edges"])
            for action in first["actions"]:
                self._start_action(action)
        for node in order["nodes"]:
            for action in node["actions"]:
                self.actions.setdefault(action["actionId"], _Action(action))
        self.errors = [e for e in self.errors if e["errorType"] != "orderError"]

    def _instant(self, action: dict[str, Any]) -> None:
        kind = action["actionType"]
        done = _Action(action, status="FINISHED")
        (self.instant_actions if self.v3 else self.actions)[action["actionId"]] = done
        params = {p["key"]: p["value"] for p in action.get("actionParameters", [])}
        if self.v3 and kind == "startHibernation":
            self._clear_order()
            self.spawn(self._hibernate(), "vda5050-sim hibernate")
            return
        if self.v3 and kind == "stopHibernation":
            if self.hibernating:
                self.hibernating = False
                self.spawn(self._hello(), "vda5050-sim wake up")
            return
        if self.v3 and kind == "enableZoneSet":
            zone_set = self.zone_sets.get(str(params.get("zoneSetId")))
            if zone_set is None:
                done.status, done.result = "FAILED", f"no zone set {params.get('zoneSetId')}"
            else:
                self.enabled[zone_set["mapId"]] = zone_set["zoneSetId"]
            return
        if kind == "cancelOrder":
            if not self.order.order_id:
                done.status = "FAILED"
                done.result = "no order to cancel"
                self._error("noOrderToCancel", "WARNING", "no order to cancel", [])
                return
            self._clear_order()
            done.status = "FINISHED"
        elif kind == "startPause":
            self.paused = True
        elif kind == "stopPause":
            self.paused = False
        elif kind == "startCharging":
            self.charging = True
        elif kind == "stopCharging":
            self.charging = False
        elif kind == "initPosition":  # after an elevator ride: on another map
            self.x, self.y = float(params["x"]), float(params["y"])
            self.theta = float(params.get("theta", 0.0))
            self.map_id, self.last_node = str(params["mapId"]), str(params["lastNodeId"])
            self.last_seq = 0
            self.order.nodes.clear()
            self.order.edges.clear()
        elif kind == "stateRequest":
            pass  # the state goes out at once (_event)
        elif kind == "factsheetRequest":
            self.spawn(self._publish_factsheet(), "vda5050-sim factsheet")
        else:
            done.status = "FAILED"
            done.result = f"unsupported instant action {kind}"

    def _clear_order(self) -> None:
        """cancelOrder, startHibernation (6.6.7): its actions FAILED, no nodes or edges left,
        its zone requests dropped; the order's ids kept."""
        for a in self.actions.values():
            if a.status in ("WAITING", "RUNNING", "INITIALIZING"):
                a.status = "FAILED"
                a.result = "order cancelled"
        self.order.nodes.clear()
        self.order.edges.clear()
        self.zone_requests = {
            r: q for r, q in self.zone_requests.items() if q["requestStatus"] == "GRANTED"
        }  # kept while it is inside the zone (6.4.3)

    async def _hibernate(self) -> None:
        """The action FINISHED in a last state, then HIBERNATING, then no state (6.2.3)."""
        await self.publish_state()
        self.hibernating = True
        self.driving = False
        await self._say("HIBERNATING")

    # -- 3.0.0 zones -----------------------------------------------------------------------
    def _take_zone_set(self, zone_set: dict[str, Any]) -> None:
        zid = zone_set["zoneSetId"]
        if zid in self.zone_sets:
            self._error("DUPLICATE_ZONE_SET", "WARNING", f"zone set {zid} already stored", [])
            return
        self.zone_sets[zid] = zone_set

    def _zones_here(self, x: float, y: float, kind: str) -> list[tuple[str, dict[str, Any]]]:
        """(zoneSetId, zone) of the enabled zone sets of its map, of ``kind``, at (x, y)."""
        zid = self.enabled.get(self.map_id)
        zone_set = self.zone_sets.get(zid or "")
        if zone_set is None:
            return []
        return [
            (zone_set["zoneSetId"], z)
            for z in zone_set["zones"]
            if z["zoneType"] == kind and inside_polygon(x, y, z["vertices"])
        ]

    def _response(self, response: dict[str, Any]) -> None:
        request = self.zone_requests.get(response["requestId"])
        if request is None:
            return
        grant = response["grantType"]
        inside = any(
            (s, z["zoneId"]) == (request["zoneSetId"], request["zoneId"])
            for s, z in self._zones_here(self.x, self.y, "RELEASE")
        )
        if grant in ("GRANTED", "QUEUED"):
            request["requestStatus"] = grant
        elif grant == "REJECTED" or not inside:
            del self.zone_requests[response["requestId"]]
        else:  # REVOKED inside: releaseLossBehavior STOP
            request["requestStatus"] = "REVOKED"
            self._error(
                "RELEASE_LOST",
                "CRITICAL",
                f"release of zone {request['zoneId']} revoked while inside",
                [("zoneId", request["zoneId"])],
            )

    def _may_enter(self, x: float, y: float) -> bool:
        """3.0.0: whether it may drive to (x, y): not into a BLOCKED zone, and into RELEASE
        zones only with a GRANTED request for each (asked for here, once)."""
        if not self.v3:
            return True
        if self._zones_here(x, y, "BLOCKED"):
            return False
        allowed = True
        for zone_set_id, zone in self._zones_here(x, y, "RELEASE"):
            mine = [
                q
                for q in self.zone_requests.values()
                if (q["zoneSetId"], q["zoneId"]) == (zone_set_id, zone["zoneId"])
            ]
            if any(q["requestStatus"] == "GRANTED" for q in mine):
                continue
            allowed = False
            if not any(q["requestStatus"] in ("REQUESTED", "QUEUED") for q in mine):
                self._requests += 1
                rid = f"r{self._requests}"
                self.zone_requests[rid] = {
                    "requestId": rid,
                    "requestType": "ACCESS",
                    "zoneId": zone["zoneId"],
                    "zoneSetId": zone_set_id,
                    "requestStatus": "REQUESTED",
                }
                self._event()
        return allowed

    def _left_zones(self) -> None:
        """3.0.0: a GRANTED request for a zone it is out of (and not driving into) is over."""
        goal = self.order.nodes[0]["nodePosition"] if self.order.nodes else None
        for rid, q in list(self.zone_requests.items()):
            if q["requestStatus"] not in ("GRANTED", "REVOKED"):
                continue
            here = {(s, z["zoneId"]) for s, z in self._zones_here(self.x, self.y, "RELEASE")}
            ahead: set[tuple[str, str]] = set()
            if goal is not None:
                ahead = {
                    (s, z["zoneId"]) for s, z in self._zones_here(goal["x"], goal["y"], "RELEASE")
                }
            key = (q["zoneSetId"], q["zoneId"])
            if key not in here and (key not in ahead or q["requestStatus"] == "REVOKED"):
                del self.zone_requests[rid]
                self._event()

    def _speed_here(self) -> float:
        """Its speed, at most the lowest SPEED_LIMIT zone it is in (3.0.0)."""
        limits = [
            float(z["maximumSpeed"]) for _, z in self._zones_here(self.x, self.y, "SPEED_LIMIT")
        ]
        return min([self.speed, *limits])

    def _start_action(self, action: dict[str, Any]) -> None:
        entry = self.actions.setdefault(action["actionId"], _Action(action))
        params = {p["key"]: p["value"] for p in action.get("actionParameters", [])}
        if action["actionType"] == "speak":
            entry.left_s = speak_seconds(str(params.get("text", "")))
        elif action["actionType"] == "wait":
            entry.left_s = float(params.get("seconds", 1.0))
        else:
            entry.status = "FAILED"
            entry.result = f"unsupported action {action['actionType']}"
            return
        entry.status = "RUNNING"

    # -- motion ----------------------------------------------------------------------------
    def _event(self) -> None:
        self._wake.set()

    async def _drive(self) -> None:
        loop = asyncio.get_running_loop()
        last = loop.time()
        while True:
            await asyncio.sleep(TICK_S)
            now = loop.time()
            dt = (now - last) * self.time_scale
            last = now
            self._step(min(dt, 0.1 * self.time_scale))

    def _step(self, dt: float) -> None:
        if self.hibernating:
            return
        if self.v3:
            self._left_zones()
        running = [a for a in self.actions.values() if a.status == "RUNNING"]
        if self.charging:
            self.battery = min(1.0, self.battery + dt / 600)
        if running:
            if not self.paused:
                for a in running:
                    a.left_s -= dt
                    if a.left_s <= 0:
                        a.status = "FINISHED"
                        self._event()
            was, self.driving = self.driving, False
            if was:
                self._event()
            return
        goal = self.order.nodes[0] if self.order.nodes else None
        if goal is None or not goal["released"] or self.paused or self.charging:
            if self.driving:
                self.driving = False
                self._event()
            return
        pos = goal["nodePosition"]
        dx, dy = pos["x"] - self.x, pos["y"] - self.y
        dist = math.hypot(dx, dy)
        step = self._speed_here() * dt
        if self.v3:
            self._may_enter(pos["x"], pos["y"])  # asks ahead for the zones of its goal
            ahead = min(1.0, step / dist) if dist > 1e-9 else 1.0
            if not self._may_enter(self.x + dx * ahead, self.y + dy * ahead):
                if self.driving:  # waits at the zone's edge for its grant
                    self.driving = False
                    self._event()
                return
        if not self.driving:
            self.driving = True
            self._event()
        self.battery = max(0.0, self.battery - dt / 7200)
        if dist > 1e-9:
            self.theta = math.atan2(dy, dx)
        if step < dist:
            self.x += dx / dist * step
            self.y += dy / dist * step
            return
        self.x, self.y, self.map_id = pos["x"], pos["y"], pos["mapId"]
        self.last_node, self.last_seq = goal["nodeId"], goal["sequenceId"]
        self.order.nodes.pop(0)
        self.order.edges = [e for e in self.order.edges if e["sequenceId"] > self.last_seq]
        for action in goal["actions"]:
            self._start_action(action)
        self._event()

    # -- state -----------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """The ``state`` message now (its version's fields)."""
        state = self._state_common()
        if not self.v3:
            return state
        position = state.pop("agvPosition")
        battery = state.pop("batteryState")
        del position["positionInitialized"]
        return state | {
            "mobileRobotPosition": position | {"localized": True},
            "powerSupply": {
                "stateOfCharge": battery["batteryCharge"],
                "charging": battery["charging"],
            },
            "instantActionStates": [a.state() for a in self.instant_actions.values()],
            "safetyState": {"activeEmergencyStop": "NONE", "fieldViolation": False},
            "zoneSets": [
                {
                    "zoneSetId": zid,
                    "mapId": zs["mapId"],
                    "zoneSetStatus": "ENABLED"
                    if self.enabled.get(zs["mapId"]) == zid
                    else "DISABLED",
                }
                for zid, zs in self.zone_sets.items()
            ],
            "zoneRequests": [dict(q) for q in self.zone_requests.values()],
        }

    def _state_common(self) -> dict[str, Any]:
        return {
            **self._header("state"),
            "orderId": self.order.order_id,
            "orderUpdateId": self.order.update_id,
            "lastNodeId": self.last_node,
            "lastNodeSequenceId": self.last_seq,
            "nodeStates": [
                {"nodeId": n["nodeId"], "sequenceId": n["sequenceId"], "released": n["released"]}
                for n in self.order.nodes
            ],
            "edgeStates": [
                {"edgeId": e["edgeId"], "sequenceId": e["sequenceId"], "released": e["released"]}
                for e in self.order.edges
            ],
            "agvPosition": {
                "x": self.x,
                "y": self.y,
                "theta": self.theta,
                "mapId": self.map_id,
                "positionInitialized": True,
            },
            "velocity": {
                "vx": self._speed_here() if self.driving else 0.0,
                "vy": 0.0,
                "omega": 0.0,
            },
            "driving": self.driving,
            "paused": self.paused,
            "actionStates": [a.state() for a in self.actions.values()],
            "batteryState": {
                "batteryCharge": round(self.battery * 100, 2),
                "charging": self.charging,
            },
            "operatingMode": "AUTOMATIC",
            "errors": list(self.errors),
            "safetyState": {"eStop": "NONE", "fieldViolation": False},
        }

    def factsheet(self) -> dict[str, Any]:
        """What the vehicle is and can do; ``speaks`` False leaves ``speak`` out of its
        actions (a vehicle without speech)."""

        def action(kind: str, scopes: list[str], params: dict[str, str]) -> dict[str, Any]:
            return {
                "actionType": kind,
                "actionScopes": scopes,
                "actionParameters": [
                    {"key": k, "valueDataType": t, "isOptional": False} for k, t in params.items()
                ],
            }

        actions = [
            action(kind, ["INSTANT"], {})
            for kind in (
                "cancelOrder",
                "startPause",
                "stopPause",
                "startCharging",
                "stopCharging",
                "stateRequest",
                "factsheetRequest",
            )
        ]
        actions.append(action("initPosition", ["INSTANT"], {"x": "FLOAT", "y": "FLOAT"}))
        actions.append(action("wait", ["NODE"], {"seconds": "FLOAT"}))
        if self.speaks:
            actions.append(action("speak", ["NODE"], {"text": "STRING", "lang": "STRING"}))
        if self.v3:
            return self._factsheet_v3(actions)
        return {
            **self._header("factsheet"),
            "typeSpecification": {
                "seriesName": "GuideBot simulated vehicle",
                "agvKinematic": "DIFF",
                "agvClass": "CARRIER",
                "maxLoadMass": 0,
                "localizationTypes": ["NATURAL"],
                "navigationTypes": ["AUTONOMOUS"],
            },
            "physicalParameters": {
                "speedMin": 0.0,
                "speedMax": self.speed,
                "accelerationMax": 1.0,
                "decelerationMax": 1.0,
                "heightMax": 1.5,
                "width": 0.6,
                "length": 0.8,
            },
            "protocolLimits": {
                "maxStringLens": {},
                "maxArrayLens": {},
                "timing": {"minOrderInterval": 0.1, "minStateInterval": self.state_period_s},
            },
            "protocolFeatures": {"optionalParameters": [], "agvActions": actions},
            "agvGeometry": {},
            "loadSpecification": {},
        }

    def _factsheet_v3(self, actions: list[dict[str, Any]]) -> dict[str, Any]:
        """The 3.0.0 factsheet: renamed fields, its zone types, hibernation."""
        numbers = {"FLOAT": "NUMBER"}
        v3_actions = [
            a
            | {
                # strings: the official 3.0.0 schema types these booleans so
                "pauseAllowed": "false",
                "cancelAllowed": "true" if "NODE" in a["actionScopes"] else "false",
                "actionParameters": [
                    p | {"valueDataType": numbers.get(p["valueDataType"], p["valueDataType"])}
                    for p in a["actionParameters"]
                ],
            }
            for a in actions
        ]
        v3_actions += [
            {
                "actionType": kind,
                "actionScopes": ["INSTANT"],
                "pauseAllowed": "false",
                "cancelAllowed": "false",
                "actionParameters": (
                    [{"key": "zoneSetId", "valueDataType": "STRING", "isOptional": False}]
                    if kind == "enableZoneSet"
                    else []
                ),
            }
            for kind in V3_INSTANT
        ]
        return {
            **self._header("factsheet"),
            "typeSpecification": {
                "seriesName": "GuideBot simulated vehicle",
                "mobileRobotKinematic": "DIFF",
                "mobileRobotClass": "CARRIER",
                "maximumLoadMass": 0,
                "localizationTypes": ["NATURAL"],
                "navigationTypes": ["AUTONOMOUS"],
                "supportedZones": list(self.supported_zones),
            },
            "physicalParameters": {
                "minimumSpeed": 0.0,
                "maximumSpeed": self.speed,
                "maximumAcceleration": 1.0,
                "maximumDeceleration": 1.0,
                "minimumHeight": 1.5,
                "maximumHeight": 1.5,
                "width": 0.6,
                "length": 0.8,
            },
            "protocolLimits": {
                "maximumStringLengths": {},
                "maximumArrayLengths": {},
                "timing": {
                    "minimumOrderInterval": 0.1,
                    "minimumStateInterval": self.state_period_s,
                },
            },
            "protocolFeatures": {"optionalParameters": [], "mobileRobotActions": v3_actions},
            "mobileRobotGeometry": {},
            "loadSpecification": {},
        }

    async def _publish_factsheet(self) -> None:
        await self._publish("factsheet", self.factsheet())

    async def publish_state(self) -> None:
        await self._publish("state", self.state())

    async def _report(self) -> None:
        while True:
            try:
                async with asyncio.timeout(self.state_period_s):
                    await self._wake.wait()
            except TimeoutError:
                pass
            self._wake.clear()
            if self.session.connected.is_set() and not self.hibernating:
                await self.publish_state()
