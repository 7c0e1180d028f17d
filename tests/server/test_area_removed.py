"""A publish that removes an area tells the robots waiting for it at once (docs/server.md,
"Lock policy"); the waits for the areas that remain keep their place. Real server, real hub
clients."""

from __future__ import annotations

import asyncio

from backend.testing import RunningServer

from .conftest import OPERATOR_TOKEN
from .test_api import Http, eventually, robot


async def test_robots_waiting_for_a_removed_area_are_told_at_once_and_others_keep_waiting(
    server: RunningServer, http: Http
) -> None:
    admin, staff = http(server.admin_token), http(OPERATOR_TOKEN)
    traffic = server.app.state.traffic
    async with (
        robot(server, "R1", "corridor_w") as r1,
        robot(server, "R2", "hall") as r2,
        robot(server, "R3", "hall") as r3,
    ):
        for area in ("corridor", "elevator"):
            grant = await r1.client.request("request_area", {"robot": "R1", "area": area})
            assert grant.type == "area_granted" and not grant.payload.get("removed")
        # Longer than the test waits: the answer must come from the publish, not a time-out.
        corridor = asyncio.create_task(
            r2.client.request("request_area", {"robot": "R2", "area": "corridor"}, timeout=60)
        )
        elevator = asyncio.create_task(
            r3.client.request("request_area", {"robot": "R3", "area": "elevator"}, timeout=60)
        )
        await eventually(
            lambda: traffic.locks.waiting_for("R2") and traffic.locks.waiting_for("R3")
        )
        document = (await admin.get("/api/site")).json()["site"]
        document["areas"] = [a for a in document["areas"] if a["id"] != "corridor"]
        # The corridor is also the demo's escape route: a site may not name a missing area.
        escape = document["emergency"]["escape_routes"]
        document["emergency"]["escape_routes"] = [e for e in escape if e != "corridor"]
        published = await admin.put("/api/site", json=document)
        assert published.status_code == 200
        told = await corridor
        assert told.type == "area_granted"
        assert told.payload["area"] == "corridor" and told.payload["removed"] is True
        assert "not on the site any more" in told.payload["reason"]
        assert traffic.locks.waiting_for("R2") is None
        assert not elevator.done() and traffic.locks.waiting_for("R3") == ("elevator",)
        locks = {lock["area"]: lock for lock in (await staff.get("/api/locks")).json()}
        assert set(locks) == {"elevator"}
        assert locks["elevator"]["holder"] == "R1" and locks["elevator"]["waiting"] == ["R3"]

        late = await r2.client.request("request_area", {"robot": "R2", "area": "corridor"})
        assert late.type == "area_granted" and late.payload["removed"] is True

        r1.client.publish("release_area", {"robot": "R1", "area": "elevator"})
        granted = await elevator
        assert granted.type == "area_granted" and granted.payload["area"] == "elevator"
        assert not granted.payload.get("removed")
        refused = await r2.client.request("request_area", {"robot": "R2", "area": "nowhere"})
        assert refused.type == "error"  # an area no site had is still a mistake
