"""The REST API against a real server, with robots connected over the hub (WebSocket)."""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import httpx

from backend.testing import RunningServer, running_server
from guidebot.client import HubClient
from guidebot.messages import Message

from .conftest import GUI_TOKEN, OPERATOR_TOKEN, PANEL_TOKEN, server_settings

GROUND: dict[str, Any] = {"kind": "tour", "params": {"tour": "ground"}}
UPSTAIRS: dict[str, Any] = {"kind": "tour", "params": {"tour": "upstairs"}}
GO_HALL: dict[str, Any] = {"kind": "go_to", "params": {"node": "hall"}}

Http = Callable[[str | None], httpx.AsyncClient]


class HubRobot:
    """A robot over the real hub: reports state, records orders, starts and ends tasks."""

    def __init__(self, client: HubClient, name: str, node: str) -> None:
        self.client, self.name, self.node = client, name, node
        self.task_id: str | None = None
        self.inbox: list[Message] = []
        self.arrived = asyncio.Event()
        for pattern in ("task_assigned", "task_cancel", "area_*"):
            client.subscribe(pattern, self._receive)

    def _receive(self, msg: Message) -> None:
        self.inbox.append(msg)
        self.arrived.set()

    async def next_order(self, net: str, timeout: float = 10.0) -> Message:
        async def find() -> Message:
            while True:
                for msg in self.inbox:
                    if msg.type == "task_assigned" and msg.payload["net"] == net:
                        return msg
                self.arrived.clear()
                await self.arrived.wait()

        return await asyncio.wait_for(find(), timeout)

    def state(self, mode: str = "idle") -> None:
        self.client.publish(
            "robot_state",
            {"robot": self.name, "node": self.node, "mode": mode, "task_id": self.task_id},
        )


@asynccontextmanager
async def robot(server: RunningServer, name: str, node: str) -> AsyncIterator[HubRobot]:
    async with HubClient(server.ws_url, f"robot-{name}-demo-token") as client:
        bot = HubRobot(client, name, node)
        await client.sync()
        bot.state()
        await client.sync()
        yield bot


async def eventually(check: Callable[[], Any], timeout: float = 10.0) -> Any:
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        value = check()
        if value:
            return value
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError("condition not met in time")
        await asyncio.sleep(0.02)


async def test_visitor_tour_from_panel_to_done(server: RunningServer, http: Http) -> None:
    panel, staff = http(PANEL_TOKEN), http(OPERATOR_TOKEN)
    tours = (await panel.get("/api/tours")).json()
    assert {t["id"] for t in tours} == {"ground", "upstairs", "highlights"}
    async with robot(server, "R1", "hall") as r1:
        created = await panel.post("/api/tasks", json=GROUND)
        assert created.status_code == 201
        task = created.json()
        order = await r1.next_order("give_tour")
        assert order.payload["task_id"] == task["id"]
        assert len(order.payload["params"]["points"]) == 5
        r1.task_id = task["id"]
        r1.client.publish("task_started", {"task_id": task["id"], "robot": "R1"})
        url = f"/api/tasks/{task['id']}"
        await eventually(lambda: server.app.state.task_manager.get(task["id"]).state == "running")
        assert (await panel.get(url)).json()["state"] == "running"
        r1.client.publish("task_ended", {"task_id": task["id"], "robot": "R1", "outcome": "done"})
        await eventually(lambda: server.app.state.task_manager.get(task["id"]).state == "done")
        status = (await panel.get(url)).json()
        assert status["state"] == "done" and status["robot"] == "R1"
        history = (await staff.get(f"{url}/history")).json()
        assert [h["state"] for h in history] == ["queued", "assigned", "running", "done"]
        events = (await staff.get("/api/events", params={"kind": "task_done"})).json()
        assert [e["data"]["task_id"] for e in events["events"]] == [task["id"]]


async def test_waiting_visitor_sees_position_and_wait(server: RunningServer, http: Http) -> None:
    panel, staff = http(PANEL_TOKEN), http(OPERATOR_TOKEN)
    async with robot(server, "R1", "hall"):
        first = (await panel.post("/api/tasks", json=GROUND)).json()
        assert first["state"] == "assigned"
        second = (
            await panel.post("/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "loom"}})
        ).json()
        assert second["queue_position"] == 1 and second["eta_s"] > 0
        urgent = (
            await staff.post(
                "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "sword"}, "priority": 9}
            )
        ).json()
        assert urgent["queue_position"] == 1
        assert (await panel.get(f"/api/tasks/{second['id']}")).json()["queue_position"] == 2
        moved = await staff.post(f"/api/tasks/{second['id']}/priority", json={"priority": 10})
        assert moved.json()["queue_position"] == 1
        listed = (await staff.get("/api/tasks", params={"state": "queued"})).json()
        assert [t["id"] for t in listed["tasks"]] == [second["id"], urgent["id"]]


async def test_reassign_running_task_off_a_dead_robot(server: RunningServer, http: Http) -> None:
    staff = http(OPERATOR_TOKEN)
    started = time.time()
    async with robot(server, "R1", "hall") as r1:
        task = (await staff.post("/api/tasks", json=GROUND)).json()
        await r1.next_order("give_tour")
        r1.task_id = task["id"]
        r1.client.publish("task_started", {"task_id": task["id"], "robot": "R1"})
        await eventually(lambda: server.app.state.task_manager.get(task["id"]).state == "running")
    # R1's link is gone (it broke down); staff move its tour to R2 at once.
    await eventually(lambda: not server.app.state.task_manager.robots["R1"].online)
    async with robot(server, "R2", "entrance") as r2:
        moved = await staff.post(f"/api/tasks/{task['id']}/reassign", json={"robot": "R2"})
        assert moved.status_code == 200
        order = await r2.next_order("give_tour")
        assert order.payload["task_id"] == task["id"]
        robots = {r["name"]: r for r in (await staff.get("/api/robots")).json()}
        assert robots["R2"]["task_id"] == task["id"] and robots["R1"]["task_id"] is None
        # last_seen is a Unix time (docs/server.md), not the Task Manager's monotonic clock.
        assert started <= robots["R1"]["last_seen"] <= robots["R2"]["last_seen"] <= time.time()
        assert robots["R3"]["last_seen"] is None


async def test_locks_listed_and_force_released_by_staff(server: RunningServer, http: Http) -> None:
    staff = http(OPERATOR_TOKEN)
    async with robot(server, "R1", "corridor_w") as r1:
        grant = await r1.client.request("request_area", {"robot": "R1", "area": "corridor"})
        assert grant.type == "area_granted"
        r1.state("busy")
        await r1.client.sync()
    await eventually(
        lambda: (
            server.app.state.traffic.lock_views()[0].state.value == "holder_offline"
            or server.app.state.task_manager.robots["R1"].online is False
        )
    )
    locks = {lock["area"]: lock for lock in (await staff.get("/api/locks")).json()}
    assert locks["corridor"]["holder"] == "R1"  # kept: it may still be inside
    released = await staff.post("/api/locks/corridor/release")
    assert released.json() == {"area": "corridor", "released_from": "R1"}
    assert (await staff.post("/api/locks/nowhere/release")).status_code == 404
    locks = {lock["area"]: lock for lock in (await staff.get("/api/locks")).json()}
    assert locks["corridor"]["state"] == "free"


async def test_roles_are_limited(server: RunningServer, http: Http) -> None:
    anonymous, panel, staff = http(None), http(PANEL_TOKEN), http(OPERATOR_TOKEN)
    gui, robot_r1, admin = http(GUI_TOKEN), http("robot-R1-demo-token"), http(server.admin_token)
    assert (await anonymous.get("/api/tours")).status_code == 401
    assert (await http("wrong-token-123").get("/api/tours")).status_code == 401
    assert (await gui.get("/api/pois")).status_code == 200
    assert (await gui.post("/api/tasks", json={"kind": "tour"})).status_code == 403
    # panel: tours, request, its own requests; nothing else
    assert (await panel.get("/api/locks")).status_code == 403
    assert (await panel.get("/api/site")).status_code == 403
    assert (await panel.get("/api/robots/R1")).status_code == 403
    assert (await panel.post("/api/tasks", json=GO_HALL)).status_code == 403
    assert (await panel.post("/api/tasks", json=GROUND | {"priority": 50})).status_code == 403
    mine = (await panel.post("/api/tasks", json=GROUND)).json()
    theirs = (await staff.post("/api/tasks", json=UPSTAIRS)).json()
    listed = (await panel.get("/api/tasks")).json()
    assert [t["id"] for t in listed["tasks"]] == [mine["id"]] and listed["total"] == 1
    assert (await panel.get(f"/api/tasks/{theirs['id']}")).status_code == 404
    assert (await panel.post(f"/api/tasks/{theirs['id']}/cancel")).status_code == 404
    assert (await panel.post(f"/api/tasks/{mine['id']}/cancel")).json()["state"] == "cancelled"
    assert (await panel.post(f"/api/tasks/{theirs['id']}/reassign", json={})).status_code == 403
    # operator: tasks, locks, robots; not the site
    assert (await staff.get("/api/tasks")).status_code == 200
    assert (await staff.get("/api/robots")).status_code == 200
    assert (await staff.get("/api/site")).status_code == 403
    assert (await staff.put("/api/pois/x", json={"id": "x", "node": "hall"})).status_code == 403
    # robot: only as itself
    assert (await robot_r1.get("/api/robots/R1")).status_code == 200
    assert (await robot_r1.get("/api/robots/R2")).status_code == 403
    assert (await robot_r1.get(f"/api/tasks/{theirs['id']}")).status_code == 404
    own = await robot_r1.post("/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "loom"}})
    assert own.json()["pinned_robot"] == "R1"
    other = await robot_r1.post(
        "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "loom"}, "robot": "R2"}
    )
    assert other.status_code == 403
    assert [t["id"] for t in (await robot_r1.get("/api/tasks")).json()["tasks"]] == [
        own.json()["id"]
    ]
    # admin: everything
    assert (await admin.get("/api/site")).status_code == 200
    assert (await admin.get("/api/locks")).status_code == 200


async def test_bad_input_is_422_unknown_ids_404(server: RunningServer, http: Http) -> None:
    staff = http(OPERATOR_TOKEN)
    bad_kind = await staff.post("/api/tasks", json={"kind": "dance"})
    assert bad_kind.status_code == 422 and bad_kind.json()["detail"]
    unknown_tour = await staff.post("/api/tasks", json={"kind": "tour", "params": {"tour": "no"}})
    assert unknown_tour.status_code == 422 and "unknown tour" in unknown_tour.json()["detail"]
    assert (await staff.post("/api/tasks", content=b"{not json")).status_code == 422
    assert (await staff.get("/api/tasks/does-not-exist")).status_code == 404
    assert (await staff.post("/api/tasks/does-not-exist/cancel")).status_code == 404
    assert (await staff.get("/api/robots/R9")).status_code == 404
    assert (await staff.get("/api/tasks", params={"limit": 0})).status_code == 422
    nowhere = {"from_node": "hall", "to_node": "x"}
    assert (await staff.get("/api/paths", params=nowhere)).status_code == 404
    assert (await staff.get("/api/tasks")).json()["total"] == 0  # nothing half-created


async def test_site_is_edited_while_running_and_broken_files_refused(
    server: RunningServer, http: Http
) -> None:
    admin, panel = http(server.admin_token), http(PANEL_TOKEN)
    poi = {"id": "harp", "name": "Harp", "node": "gc3", "text": "A harp.", "media": ["harp.mp3"]}
    assert (await admin.put("/api/pois/harp", json=poi)).status_code == 200
    tour = {"id": "music", "name": "Music", "points": ["harp", "globes"]}
    assert (await admin.put("/api/tours/music", json=tour)).status_code == 200
    assert "music" in {t["id"] for t in (await panel.get("/api/tours")).json()}
    task = await panel.post("/api/tasks", json={"kind": "tour", "params": {"tour": "music"}})
    assert task.status_code == 201
    refused = await admin.delete("/api/pois/harp")  # the tour still uses it
    assert refused.status_code == 422
    assert any("harp" in d["msg"] for d in refused.json()["detail"])
    bad_tour = await admin.put("/api/tours/bad", json={"id": "bad", "points": ["nope"]})
    assert bad_tour.status_code == 422
    exported = await admin.get("/api/site/export")
    assert "harp" in exported.text
    broken = exported.text.replace("node: gc3", "node: attic", 1).replace(
        "unit_id: 1", "unit_id: 999", 1
    )
    answer = await admin.post("/api/site/import", content=broken.encode())
    assert answer.status_code == 422
    problems = answer.json()["detail"]
    assert len(problems) >= 1 and all(p["line"] for p in problems)
    version = (await admin.get("/api/site")).json()["version"]
    assert (await admin.post("/api/site/import", content=exported.content)).json() == {
        "version": version + 1
    }
    assert (await admin.get("/api/pois/harp")).status_code == 200


async def test_restart_keeps_queued_and_reconciles_running(tmp_path: Path, db_url: str) -> None:
    settings = server_settings(tmp_path, db_url)
    headers = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
    async with running_server(settings) as srv:
        async with httpx.AsyncClient(base_url=srv.url, headers=headers) as staff:
            async with robot(srv, "R1", "hall") as r1, robot(srv, "R2", "ga1") as r2:
                ids = []
                for bot, tour in ((r1, "ground"), (r2, "highlights")):
                    t = (
                        await staff.post(
                            "/api/tasks",
                            json={"kind": "tour", "params": {"tour": tour}, "robot": bot.name},
                        )
                    ).json()
                    await bot.next_order("give_tour")
                    bot.task_id = t["id"]
                    bot.client.publish("task_started", {"task_id": t["id"], "robot": bot.name})
                    ids.append(t["id"])
                queued = (
                    await staff.post(
                        "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "loom"}}
                    )
                ).json()
                assert queued["state"] == "queued"
                manager = srv.app.state.task_manager
                await eventually(lambda: all(manager.get(i).state == "running" for i in ids))
    async with running_server(settings) as srv:
        manager = srv.app.state.task_manager
        assert manager.get(queued["id"]).state == "queued"
        assert [manager.get(i).state for i in ids] == ["running", "running"]
        async with robot(srv, "R1", "ga2") as r1:
            r1.task_id = ids[0]
            r1.state("busy")  # still running its tour
            async with robot(srv, "R2", "ga1"):  # lost its tour in the meantime
                await eventually(lambda: manager.get(ids[1]).state != "running")
                assert manager.get(ids[0]).state == "running"
                assert manager.get(ids[1]).robot != "R1"


async def test_robot_added_to_the_site_can_connect_at_once(
    server: RunningServer, http: Http
) -> None:
    admin, staff = http(server.admin_token), http(OPERATOR_TOKEN)
    document = (await admin.get("/api/site")).json()["site"]
    document["robots"].append({"name": "R4", "token": "robot-R4-new-token", "start_node": "hall"})
    document["robots"] = [r for r in document["robots"] if r["name"] != "R3"]
    assert (await admin.put("/api/site", json=document)).status_code == 200
    async with HubClient(server.ws_url, "robot-R4-new-token") as client:
        await client.sync()
        assert client.name == "R4"
    assert (await http("robot-R3-demo-token").get("/api/tours")).status_code == 401
    names = {r["name"] for r in (await staff.get("/api/robots")).json()}
    assert names == {"R1", "R2", "R4"}


async def test_a_site_body_that_is_not_a_json_object_is_refused_and_changes_nothing(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    before = (await admin.get("/api/site")).json()
    broken = await admin.put(
        "/api/site", content=b'{"name": ', headers={"Content-Type": "application/json"}
    )
    assert broken.status_code == 422 and "not valid JSON" in broken.json()["detail"]
    listed = await admin.put("/api/site", json=[before["site"]])
    assert listed.status_code == 422 and "JSON object" in listed.json()["detail"]
    assert (await admin.get("/api/site")).json() == before


async def test_events_are_paged(server: RunningServer, http: Http) -> None:
    staff = http(OPERATOR_TOKEN)
    for _ in range(3):
        await staff.post("/api/tasks", json=GROUND)
    first = (await staff.get("/api/events", params={"limit": 2})).json()
    assert len(first["events"]) == 2
    rest = (await staff.get("/api/events", params={"after_id": first["next_after_id"]})).json()
    ids = [e["id"] for e in first["events"] + rest["events"]]
    assert ids == sorted(set(ids)) and len(ids) >= 3


async def test_path_across_floors_through_doors_over_rest_and_hub(
    server: RunningServer, http: Http
) -> None:
    staff = http(OPERATOR_TOKEN)
    path = (await staff.get("/api/paths", params={"from_node": "gb1", "to_node": "gc3"})).json()
    doors = [s["door"] for s in path["steps"] if s["door"]]
    assert doors == ["door_gallery", "door_upstairs"]
    assert path["areas"] == ["corridor", "elevator"]
    assert {s["floor"] for s in path["steps"]} == {"F0", "F1"}
    async with robot(server, "R2", "gb1") as r2:
        reply = await r2.client.request("get_path", {"robot": "R2", "to_node": "gc3"})
        assert reply.payload["nodes"] == path["nodes"]  # from its reported position
