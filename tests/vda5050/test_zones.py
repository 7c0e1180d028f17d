"""VDA 5050 3.0.0 (docs/vda5050.md, "Version 3.0.0: zones"): a vehicle whose site entry says
3.0.0 gets the site's restricted areas as a zoneSet of RELEASE zones (then enableZoneSet), and
its zone requests are answered on ``responses`` through the Traffic Manager's lock table
(QUEUED while another robot holds the area, GRANTED when it has it, REJECTED for a zone that
is not ours); its 3.0.0 state (``mobileRobotPosition``, ``powerSupply``) is the robot's state,
and an order for it is a 3.0.0 order. The vehicle is played by hand over a real Mosquitto;
everything sent or received is checked against the official 3.0.0 schemas."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import aiomqtt
import pytest

from guidebot.payloads.traffic import ReleaseArea, RequestArea
from guidebot.testing import wait_on, wait_until
from guidebot.vda5050.schemas import problems
from guidebot.vda5050.topics import Vehicle

from .broker import Mosquitto, mosquitto
from .fleet import V1, Fleet, fleet

pytestmark = pytest.mark.timeout(90)

V3 = Vehicle(V1.manufacturer, V1.serial_number, version="3.0.0")
X = {"a": 0.0, "b": 4.0, "c": 8.0, "d": 12.0, "e": 16.0}


@pytest.fixture
def broker() -> Iterator[Mosquitto]:
    with mosquitto() as b:
        yield b


class Hand:
    """A 3.0.0 vehicle played by the test: what it receives, by topic; states it sends."""

    def __init__(self, client: aiomqtt.Client, topics: Vehicle) -> None:
        self.client, self.topics = client, topics
        self.got: dict[str, list[dict[str, Any]]] = {}
        self.changed = asyncio.Event()
        self.headers = 0

    def of(self, topic: str) -> list[dict[str, Any]]:
        return self.got.get(topic, [])

    async def listen(self) -> None:
        async for message in self.client.messages:
            topic = str(message.topic).rsplit("/", 1)[-1]
            body = json.loads(bytes(message.payload))  # type: ignore[arg-type]
            # its own version: before the vehicle's first word the master speaks the site's
            assert problems(topic, body) == [], (topic, body)
            self.got.setdefault(topic, []).append(body)
            self.changed.set()

    async def send(self, topic: str, body: dict[str, Any]) -> None:
        self.headers += 1
        message = {**V3.header(self.headers), **body}
        assert problems(topic, message, "3.0.0") == [], message
        await self.client.publish(self.topics.topic(topic), json.dumps(message), qos=1)

    async def state(self, node: str = "a", **more: Any) -> None:
        await self.send(
            "state",
            {
                "orderId": "",
                "orderUpdateId": 0,
                "lastNodeId": node,
                "lastNodeSequenceId": 0,
                "nodeStates": [],
                "edgeStates": [],
                "mobileRobotPosition": {
                    "x": X[node],
                    "y": 0.0,
                    "theta": 0.0,
                    "mapId": "ground",
                    "localized": True,
                },
                "driving": False,
                "paused": False,
                "actionStates": [],
                "instantActionStates": [],
                "powerSupply": {"stateOfCharge": 80.0, "charging": False},
                "operatingMode": "AUTOMATIC",
                "errors": [],
                "safetyState": {"activeEmergencyStop": "NONE", "fieldViolation": False},
            }
            | more,
        )

    def answers(self, request_id: str) -> list[str]:
        return [
            r["grantType"]
            for m in self.of("responses")
            for r in m["responses"]
            if r["requestId"] == request_id
        ]


@contextlib.asynccontextmanager
async def hand(broker: Mosquitto, topics: Vehicle) -> AsyncIterator[Hand]:
    async with aiomqtt.Client("127.0.0.1", broker.port, identifier="hand-v3") as client:
        await client.subscribe(topics.topic("#"))
        h = Hand(client, topics)
        listener = asyncio.get_running_loop().create_task(h.listen())
        try:
            yield h
        finally:
            listener.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await listener


def request(rid: str, zone_set: str, zone: str, status: str = "REQUESTED") -> dict[str, Any]:
    return {
        "requestId": rid,
        "requestType": "ACCESS",
        "zoneId": zone,
        "zoneSetId": zone_set,
        "requestStatus": status,
    }


@pytest.mark.parametrize("site_says", ["3.0.0", "2.1.0"])
async def test_zones_for_a_3_0_0_vehicle_answered_through_the_lock_table(
    tmp_path: Path, broker: Mosquitto, site_says: str
) -> None:
    """The site's entry says 3.0.0 (topics uagv/v3/...), or says nothing (2.1.0, topics
    uagv/v2/...) while the vehicle's messages declare 3.0.0: its declared version chooses."""
    topics = Vehicle(V1.manufacturer, V1.serial_number, version=site_says)
    v1 = {"vda_version": site_says}
    async with fleet(tmp_path, broker.url, v1=v1) as f, hand(broker, topics) as v:
        await v.send("connection", {"connectionState": "ONLINE"})
        await v.state()
        await wait_on(v.changed, lambda: v.of("zoneSet") and v.of("instantActions"), 15)
        (zone_set,) = [m["zoneSet"] for m in v.of("zoneSet")]
        assert zone_set["mapId"] == "ground"
        (zone,) = zone_set["zones"]
        assert (zone["zoneId"], zone["zoneType"]) == ("corridor", "RELEASE")
        xs = sorted({p["x"] for p in zone["vertices"]})
        assert xs == [7.0, 13.0]  # c and d, one metre wider
        zid = zone_set["zoneSetId"]

        def enabled() -> list[str]:
            return [
                p["value"]
                for m in v.of("instantActions")
                for a in m["actions"]
                if a["actionType"] == "enableZoneSet"
                for p in a["actionParameters"]
            ]

        await wait_on(v.changed, lambda: enabled() == [zid], 15)
        state = await robot_state(f)
        assert (state["node"], state["battery"], state["x"]) == ("a", 0.8, 0.0)

        other = f.server.app.state.hub.endpoint("R1")
        other.publish(RequestArea(robot="R1", area="corridor"))
        traffic = f.server.app.state.traffic
        await wait_until(lambda: traffic.locks.holder("corridor") == "R1")
        enabled_set = [{"zoneSetId": zid, "mapId": "ground", "zoneSetStatus": "ENABLED"}]
        asking = [request("r1", zid, "corridor"), request("r2", zid, "nowhere")]
        await v.state("b", zoneSets=enabled_set, zoneRequests=asking)
        await wait_on(v.changed, lambda: v.answers("r1") == ["QUEUED"], 15)
        await wait_on(v.changed, lambda: v.answers("r2") == ["REJECTED"], 15)
        assert traffic.locks.holder("corridor") == "R1"
        other.publish(ReleaseArea(robot="R1", area="corridor"))
        await wait_on(v.changed, lambda: v.answers("r1") == ["QUEUED", "GRANTED"], 15)
        assert traffic.locks.holder("corridor") == "V1"
        inside = [request("r1", zid, "corridor", "GRANTED")]
        await v.state("c", zoneSets=enabled_set, zoneRequests=inside)
        await v.state("e", zoneSets=enabled_set, zoneRequests=[])  # out of the zone
        await wait_until(lambda: traffic.locks.holder("corridor") is None, 15)
        assert len(v.of("zoneSet")) == 1 and enabled() == [zid]  # once: the vehicle has it
        assert {m["version"] for m in v.of("zoneSet") + v.of("responses")} == {"3.0.0"}
        other.close()


async def robot_state(f: Fleet) -> dict[str, Any]:
    def seen() -> bool:
        return any(m.payload["robot"] == "V1" for m in f.of("robot_state"))

    await wait_on(f.changed, seen, 15)
    return next(m.payload for m in reversed(f.of("robot_state")) if m.payload["robot"] == "V1")


async def granted_inside(f: Fleet, v: Hand) -> tuple[str, list[dict[str, Any]]]:
    """V1 (3.0.0) has the corridor's zone set enabled, asked for the corridor (r1), was
    granted it, and reports itself inside (r1 GRANTED). Returns (zoneSetId, zoneSets)."""
    await v.send("connection", {"connectionState": "ONLINE"})
    await v.state()
    await wait_on(v.changed, lambda: v.of("zoneSet"), 15)
    zid = v.of("zoneSet")[-1]["zoneSet"]["zoneSetId"]
    enabled_set = [{"zoneSetId": zid, "mapId": "ground", "zoneSetStatus": "ENABLED"}]
    await v.state("b", zoneSets=enabled_set, zoneRequests=[request("r1", zid, "corridor")])
    await wait_on(v.changed, lambda: "GRANTED" in v.answers("r1"), 15)
    traffic = f.server.app.state.traffic
    assert traffic.locks.holder("corridor") == "V1"
    inside = [request("r1", zid, "corridor", "GRANTED")]
    await v.state("c", zoneSets=enabled_set, zoneRequests=inside)
    return zid, enabled_set


async def test_a_grant_staff_take_back_is_revoked(tmp_path: Path, broker: Mosquitto) -> None:
    """Staff release the corridor by hand while V1 is inside with its grant: the lock table
    took it back, so the vehicle's request is answered REVOKED (and only once)."""
    topics = Vehicle(V1.manufacturer, V1.serial_number, version="3.0.0")
    async with (
        fleet(tmp_path, broker.url, v1={"vda_version": "3.0.0"}) as f,
        hand(broker, topics) as v,
    ):
        zid, enabled_set = await granted_inside(f, v)
        answer = await f.http.post("/api/locks/corridor/release")
        assert answer.status_code == 200, answer.text
        assert answer.json()["released_from"] == "V1"
        inside = [request("r1", zid, "corridor", "GRANTED")]
        await v.state("c", zoneSets=enabled_set, zoneRequests=inside)
        await wait_on(v.changed, lambda: v.answers("r1")[-1:] == ["REVOKED"], 15)
        await v.state("c", zoneSets=enabled_set, zoneRequests=inside)  # not yet read
        revoked = [request("r1", zid, "corridor", "REVOKED")]
        await v.state("c", zoneSets=enabled_set, zoneRequests=revoked)
        await robot_state(f)
        assert v.answers("r1").count("REVOKED") == 1
        assert f.server.app.state.traffic.locks.holder("corridor") is None


async def test_a_closure_is_a_blocked_zone_and_revokes_the_grant(
    tmp_path: Path, broker: Mosquitto
) -> None:
    """Staff close the corridor: V1 gets a new zone set with a BLOCKED zone over it (then
    enableZoneSet), its granted request is REVOKED, a new request REJECTED; reopened, the
    BLOCKED zone is gone again."""
    topics = Vehicle(V1.manufacturer, V1.serial_number, version="3.0.0")
    async with (
        fleet(tmp_path, broker.url, v1={"vda_version": "3.0.0"}) as f,
        hand(broker, topics) as v,
    ):
        zid, enabled_set = await granted_inside(f, v)
        await v.state("b", zoneSets=enabled_set, zoneRequests=[])  # out again, at b
        await wait_until(lambda: f.server.app.state.traffic.locks.holder("corridor") is None)
        await v.state("b", zoneSets=enabled_set, zoneRequests=[request("r2", zid, "corridor")])
        await wait_on(v.changed, lambda: "GRANTED" in v.answers("r2"), 15)
        inside = [request("r2", zid, "corridor", "GRANTED")]
        await v.state("b", zoneSets=enabled_set, zoneRequests=inside)
        body = {"kind": "area", "target": "corridor", "reason": "a school group"}
        answer = await f.http.post("/api/closures", json=body)
        assert answer.status_code == 201, answer.text
        await wait_on(v.changed, lambda: len(v.of("zoneSet")) == 2, 15)
        blocked = v.of("zoneSet")[-1]["zoneSet"]
        types = {z["zoneId"]: z["zoneType"] for z in blocked["zones"]}
        assert types == {"corridor": "RELEASE", "closed:corridor": "BLOCKED"}
        assert blocked["zoneSetId"] != zid
        await wait_on(v.changed, lambda: blocked["zoneSetId"] in enabled_ids(v), 15)
        both = [  # one zone set enabled per map: the new one
            {**enabled_set[0], "zoneSetStatus": "DISABLED"},
            {**enabled_set[0], "zoneSetId": blocked["zoneSetId"]},
        ]
        await v.state("b", zoneSets=both, zoneRequests=inside)
        await wait_on(v.changed, lambda: v.answers("r2")[-1:] == ["REVOKED"], 15)
        asking = [request("r3", blocked["zoneSetId"], "corridor")]
        await v.state("b", zoneSets=both, zoneRequests=asking)
        await wait_on(v.changed, lambda: v.answers("r3") == ["REJECTED"], 15)
        await f.http.delete(f"/api/closures/{answer.json()['id']}")
        # The set without the BLOCKED zone is the first one again: the vehicle has it (its
        # state says so), so it is enabled again, not sent twice (DUPLICATE_ZONE_SET).
        await v.state("b", zoneSets=both, zoneRequests=[])
        await wait_on(v.changed, lambda: enabled_ids(v)[-1:] == [zid], 15)
        assert len(v.of("zoneSet")) == 2


def enabled_ids(v: Hand) -> list[str]:
    """The zone sets the master enabled (enableZoneSet), in order."""
    return [
        p["value"]
        for m in v.of("instantActions")
        for a in m["actions"]
        if a["actionType"] == "enableZoneSet"
        for p in a["actionParameters"]
    ]
