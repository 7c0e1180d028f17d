"""What an operator met using the console on the busy demo (docs/console.md), in a real browser
against a real server: a paused fleet's queue says why nothing starts; a robot's place is where
it is, not the last node it passed; the event log's type filter lists one entry per type; a
robot out of service says so on the map; an evacuation says "safe near Tapestries", not
"safe at near Tapestries".

The robots are the site's robots' hub links driven by the test (test_console_steady.py's way):
where each one is, is known exactly."""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import AsyncIterator
from types import SimpleNamespace
from typing import Any

import orjson
import pytest
import websockets
from playwright.async_api import expect

from guidebot.testing import wait_until

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


def quiet_site(data: dict[str, Any]) -> None:
    """No wait point: the Task Manager sends no idle robot anywhere."""
    data["wait_points"] = []


class Link:
    """A robot's hub link; ``send`` publishes a message as that robot (its state is repeated
    every second: the server counts a robot silent for 10 s as lost)."""

    def __init__(self, name: str, ws: Any) -> None:
        self.name = name
        self.ws = ws
        self.seq = 0
        self.state: dict[str, Any] | None = None
        self.repeat: asyncio.Task[None] | None = None

    async def send(self, kind: str, payload: dict[str, Any]) -> None:
        self.seq += 1
        message = {"type": kind, "id": f"{self.name}-{self.seq}", "timestamp": time.time()}
        await self.ws.send(orjson.dumps({**message, "payload": payload}).decode())

    async def stand(self, floor: str, x: float, y: float, node: str) -> None:
        self.state = {
            "robot": self.name, "x": x, "y": y, "theta": 0.0, "floor": floor,
            "node": node, "battery": 0.9, "mode": "idle",
        }  # fmt: skip
        await self.send("robot_state", {**self.state, "seq": self.seq})
        if self.repeat is None:
            self.repeat = asyncio.create_task(self.keep())

    async def keep(self) -> None:
        while True:
            await asyncio.sleep(1.0)
            assert self.state is not None
            await self.send("robot_state", {**self.state, "seq": self.seq})


@contextlib.asynccontextmanager
async def robot_link(fleet: Any, demo_site: Any, name: str) -> AsyncIterator[Link]:
    token = next(r.token for r in demo_site.robots if r.name == name)
    url = f"{fleet.server.ws_url}?token={token}"
    async with websockets.connect(url, proxy=None) as ws:
        await ws.recv()  # welcome
        link = Link(name, ws)
        try:
            yield link
        finally:
            if link.repeat is not None:
                link.repeat.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await link.repeat


async def test_a_paused_fleets_queue_says_why_nothing_starts(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The queue's ETA column said "—" for every task while the fleet was paused."""
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        async with fleet.http(web.operator_token) as http:
            reply = await http.post("/api/fleet/pause", json={"reason": "lunch break"})
            assert reply.status_code == 200, reply.text
            reply = await http.post(
                "/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}}
            )
            assert reply.status_code == 201, reply.text
            task = reply.json()["id"]
        await web.open_view(page, "Tasks")
        row = page.locator(f'table[aria-label="Queued tasks"] tr[data-task="{task}"]')
        await expect(row.get_by_role("cell").nth(4)).to_have_text("fleet paused")
        await expect(page.locator("#queue-paused")).to_contain_text("lunch break")
        await web.axe_check(page)
        async with fleet.http(web.operator_token) as http:
            assert (await http.post("/api/fleet/resume")).status_code == 200
        await expect(page.locator("#queue-paused")).to_have_count(0)


async def test_a_robots_place_is_where_it_is_and_out_of_service_says_so(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Any
) -> None:
    """R1 left the Welcome hall (its last node) and is 1.4 m from the lift: the Robots view and
    the map's details said "Welcome hall" all the way. Taken out of service, its tooltip said
    "idle", as for a robot free to take a task."""
    async with fleet_factory(robots=0, edit=quiet_site) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        async with robot_link(fleet, demo_site, "R1") as r1:
            await r1.stand("F0", 5.0, 6.6, "hall")  # on its way from hall (5, 0) to lift0 (5, 8)
            marker = page.get_by_role("button", name="robot R1")
            await expect(marker).to_be_visible(timeout=20_000)
            await marker.dispatch_event("click")
            where = page.locator("#details dt", has_text="Where")
            await expect(where.locator("xpath=following-sibling::dd[1]")).to_have_text(
                "near elevator lift (Ground floor)"
            )
            async with fleet.http(web.operator_token) as http:
                reply = await http.post("/api/robots/R1/service", json={"out_of_service": True})
                assert reply.status_code == 200, reply.text
            await expect(marker).to_have_attribute(
                "title", "R1: out of service, idle, battery 90 %"
            )
            await expect(page.locator("#details")).to_contain_text("out of service")
            await web.open_view(page, "Robots")
            pose = page.locator("#robot-R1").locator("xpath=..").locator("dt", has_text="Pose")
            await expect(pose.locator("xpath=following-sibling::dd[1]")).to_contain_text(
                "near elevator lift, Ground floor"
            )


async def test_the_event_logs_type_filter_lists_each_type_once(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """A tour's progress is logged as "task_point 2/5 arrived": the filter listed one type per
    stop and stage, a long list by the afternoon; now "task_point" once, showing them all."""
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        store = fleet.server.app.state.store
        for i, stage in [(1, "arrived"), (1, "explained"), (2, "arrived")]:
            data = {"task_id": "t1", "robot": "R1", "index": i, "total": 5, "stage": stage}
            store.record_event(f"task_point {i}/5 {stage}", "task_manager", data)
        await web.open_view(page, "Event log")
        rows = page.get_by_role("table", name="Events").get_by_role("row")
        await expect(rows.filter(has_text="task_point")).to_have_count(3)
        kinds = page.get_by_label("Type")
        options = await kinds.locator("option").all_inner_texts()
        assert [o for o in options if o.startswith("task_point")] == ["task_point"], options
        await kinds.select_option("task_point")
        await expect(rows.filter(has_text="task_point")).to_have_count(3)
        await expect(page.locator("#event-count")).to_contain_text("3 events loaded")


async def test_an_evacuation_near_a_point_reads_well(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Any
) -> None:
    """R1 safe at the landing, a node named by the point nearest it: "safe near Tapestries"
    (the banner said "safe at near Tapestries")."""
    async with fleet_factory(robots=0, edit=quiet_site) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        async with robot_link(fleet, demo_site, "R1") as r1:
            await r1.stand("F1", 5.0, 4.0, "landing")
            known = fleet.server.app.state.task_manager.robots
            await wait_until(lambda: known["R1"].node == "landing")
            async with fleet.http(web.operator_token) as http:
                reply = await http.post("/api/emergency/declare", json={"reason": "drill"})
                assert reply.status_code == 200, reply.text
            banner = page.locator("#emergency-banner")
            await expect(banner).to_be_visible()
            await r1.send("evacuation_state", {"state": "safe", "node": "landing"})
            await expect(banner.locator('[data-evacuation="R1"]')).to_have_text(
                "R1: safe near Tapestries"
            )
