"""A reload's snapshot answered late (a reconnect on a slow network) against what came live
meanwhile, in a real browser against a real server: the fleet's pause, a fire alarm, a new
task, a robot taken out of service each stay as the live message said, not as the older
snapshot did; and a robot's task is what its own state says, not what the snapshot of
sign-in said."""

from __future__ import annotations

import asyncio
import re
import time
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from tests.web.test_console_truth import LiveConnection

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

MARK = "snapshot mark"


class LateSnapshot:
    """The page's next reload, held back: its answer to ``held`` is fetched from the server
    when the page asks and delivered only at ``release()``; the same reload's alerts carry a
    mark (an alert only this snapshot has), so the test sees when the page has taken it."""

    def __init__(self, page: Any, held: Callable[[str], bool]) -> None:
        self.page = page
        self.held = held
        self.fetched = asyncio.Event()
        self.go = asyncio.Event()
        self.marked = False

    async def hold(self) -> None:
        await self.page.route(lambda url: self.held(url), self._late)
        await self.page.route("**/api/alerts?include_acked=true", self._mark)

    async def _late(self, route: Any) -> None:
        if self.fetched.is_set():  # only the reload this test holds back
            await route.continue_()
            return
        response = await route.fetch()  # as the server says now, before the live change
        self.fetched.set()
        await self.go.wait()
        await route.fulfill(response=response)

    async def _mark(self, route: Any) -> None:
        if self.marked:
            await route.continue_()
            return
        self.marked = True
        response = await route.fetch()
        now = time.time()
        mark = {
            "id": "mark", "kind": "test_mark", "subject": "", "message": MARK,
            "severity": "warning", "raised_at": now, "last_seen": now + 3600, "count": 1,
            "lasting": True, "acked_by": None, "acked_at": None, "resolved_at": None,
            "resolution": None, "updated_at": now,
        }  # fmt: skip
        await route.fulfill(response=response, json=[*(await response.json()), mark])

    async def release(self) -> None:
        """Deliver the held answer; return once the page drew that snapshot."""
        self.go.set()
        await expect(self.page.locator("#alert-bar")).to_contain_text(MARK)


async def reloading_late(
    page: Any, hub: LiveConnection, held: Callable[[str], bool]
) -> LateSnapshot:
    """Drop the live connection: the page reconnects and its reload waits at ``held``."""
    late = LateSnapshot(page, held)
    await late.hold()
    await hub.drop()
    await late.fetched.wait()
    return late


async def signed_in(fleet: Any, open_page: Any, web: SimpleNamespace) -> tuple[Any, LiveConnection]:
    watch = await open_page("")
    page = watch.page
    hub = await LiveConnection.route(page)
    await page.goto(fleet.admin_url)
    await web.sign_in(watch, fleet.server.admin_token)
    return page, hub


def path_is(path: str) -> Callable[[str], bool]:
    return lambda url: url.split("://", 1)[-1].partition("/")[2] == path.lstrip("/")


async def test_a_snapshot_fetched_before_the_fleet_was_paused_does_not_resume_it(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet, fleet.http() as http:
        page, hub = await signed_in(fleet, open_page, web)
        await web.open_view(page, "Fleet")
        state = page.locator("#fleet-state")
        await expect(state).to_contain_text("running")
        late = await reloading_late(page, hub, path_is("/api/fleet"))
        reply = await http.post("/api/fleet/pause", json={"reason": "staff meeting"})
        assert reply.status_code == 200, reply.text
        await expect(state).to_contain_text("paused")
        await late.release()
        await expect(state).to_contain_text("paused")
        await expect(state).to_contain_text("staff meeting")
        assert (await http.get("/api/fleet")).json()["paused"] is True


async def test_a_snapshot_fetched_before_a_fire_alarm_does_not_take_the_banner_away(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet, fleet.http() as http:
        page, hub = await signed_in(fleet, open_page, web)
        banner = page.locator("#emergency-banner")
        await expect(banner).to_be_hidden()
        late = await reloading_late(page, hub, path_is("/api/emergency"))
        reply = await http.post("/api/emergency/declare", json={"reason": "smoke in hall"})
        assert reply.status_code == 200, reply.text
        await expect(banner).to_contain_text("smoke in hall", timeout=20_000)
        await late.release()
        await expect(banner).to_be_visible()
        await expect(banner).to_contain_text("smoke in hall")
        await expect(
            page.get_by_role("button", name="Declare emergency", exact=True)
        ).to_have_count(0)


async def test_a_task_listing_fetched_before_a_task_was_requested_does_not_take_it_away(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet, fleet.http() as http:
        page, hub = await signed_in(fleet, open_page, web)
        await web.open_view(page, "Tasks")
        await expect(page.get_by_text("The queue is empty.")).to_be_visible()
        listing = re.compile(r"/api/tasks\?limit=")
        late = await reloading_late(page, hub, lambda url: bool(listing.search(url)))
        reply = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}})
        assert reply.status_code == 201, reply.text
        row = page.locator(f'tr[data-task="{reply.json()["id"]}"]')
        await expect(row).to_be_visible()
        await late.release()
        await expect(row).to_be_visible()
        await expect(row).to_contain_text("Tour: Ground floor tour")


async def test_a_snapshot_fetched_before_a_robot_left_service_does_not_put_it_back(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet, fleet.http() as http:
        page, hub = await signed_in(fleet, open_page, web)
        await web.open_view(page, "Robots")
        heading = page.get_by_role("heading", name="R1")
        await expect(heading).to_contain_text("online", timeout=20_000)
        late = await reloading_late(page, hub, path_is("/api/robots"))
        reply = await http.post("/api/robots/R1/service", json={"out_of_service": True})
        assert reply.status_code == 200, reply.text
        await expect(heading).to_contain_text("out of service")
        await late.release()
        await expect(heading).to_contain_text("out of service")
        await expect(page.get_by_role("button", name="Put R1 back in service")).to_be_visible()


async def test_a_robot_whose_task_ended_shows_no_task_though_it_had_one_at_sign_in(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The snapshot of sign-in names the task R1 ran then; once R1 says it runs none, the
    Robots view and the map's details say none, and offer no "Cancel R1's task"."""
    async with fleet_factory(robots=1, time_scale=1.0) as fleet, fleet.http() as http:
        reply = await http.post(
            "/api/tasks", json={"kind": "go_to", "params": {"node": "gc3"}, "robot": "R1"}
        )  # upstairs, by the lift: a long way at time scale 1
        assert reply.status_code == 201, reply.text
        task = reply.json()["id"]
        watch = await open_page("")
        page = watch.page
        await page.goto(fleet.admin_url)
        robots = path_is("/api/robots")
        async with page.expect_response(lambda r: robots(r.url)) as snapshot:
            await web.sign_in(watch, fleet.server.admin_token)
        r1 = next(r for r in await (await snapshot.value).json() if r["name"] == "R1")
        assert r1["task_id"] == task  # the sign-in's snapshot names it
        await web.open_view(page, "Robots")
        card = page.get_by_role("region", name="R1")
        await expect(card).to_contain_text("Go to: Telescope", timeout=20_000)
        reply = await http.post(f"/api/tasks/{task}/cancel", json={"reason": "test"})
        assert reply.status_code == 200, reply.text
        task_line = card.locator("dt", has_text="Task").locator("xpath=following-sibling::dd[1]")
        await expect(task_line).to_have_text("none", timeout=20_000)
        await expect(card.get_by_role("button", name="Cancel R1's task")).to_have_count(0)
        await web.open_view(page, "Map")
        # The element, not a point: a moving marker (or one moved aside) can be missed.
        await page.get_by_role("button", name="robot R1").dispatch_event("click")
        details = page.locator("#details")
        await expect(details).to_contain_text("Robot R1")
        await expect(
            details.locator("dt", has_text="Task").locator("xpath=following-sibling::dd[1]")
        ).to_have_text("none")
