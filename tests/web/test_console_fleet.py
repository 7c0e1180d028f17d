"""The console's controls for a busy day (issue 33): pause the whole fleet and resume, send
every robot home, open a door and call an elevator by hand (logged with who), every floor at
once."""

from __future__ import annotations

import re
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(150)]


async def logged(http: httpx.AsyncClient, kind: str) -> list[dict[str, Any]]:
    reply = await http.get("/api/events", params={"kind": kind, "latest": "true"})
    return [row["data"] for row in reply.json()["events"]]


async def test_pause_resume_and_send_every_robot_home(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        await expect(page.get_by_role("button", name="robot R1")).to_be_visible(timeout=20_000)
        await web.open_view(page, "Fleet")
        state = page.locator("#fleet-state")
        await expect(state).to_contain_text("running")
        await page.get_by_label("Reason").fill("fire drill")
        await page.get_by_role("button", name="Pause the fleet").click()
        await expect(state).to_contain_text("paused by desk")
        await expect(state).to_contain_text("fire drill")
        async with fleet.http() as http:
            assert (await http.get("/api/fleet")).json()["paused"] is True
            reply = await http.post(
                "/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}}
            )
            task = reply.json()
            assert task["state"] == "queued"  # R1 is free, but the fleet is paused
            await page.get_by_role("button", name="Resume the fleet").click()
            await expect(state).to_contain_text("running")
            await web.open_view(page, "Tasks")
            running = page.get_by_role("table", name="Running tasks")
            await expect(running.locator(f'tr[data-task="{task["id"]}"]')).to_be_visible(
                timeout=20_000
            )
            assert await logged(http, "fleet_paused") == [{"by": "desk", "reason": "fire drill"}]
            assert await logged(http, "fleet_resumed") == [{"by": "desk"}]
            await web.open_view(page, "Fleet")
            await page.get_by_role("button", name="Send every robot home").click()
            dialog = page.get_by_role("dialog", name="Send every robot home?")
            await expect(dialog).to_be_visible()
            await dialog.get_by_role("button", name="Send every robot home").click()
            await expect(
                page.get_by_role("status").filter(has_text="Send every robot home: done")
            ).to_be_visible()
            tasks = (await http.get("/api/tasks", params={"limit": 50})).json()["tasks"]
            charge = [t for t in tasks if t["kind"] == "charge" and not t["internal"]]
            assert [(t["pinned_robot"], t["requester"]) for t in charge] == [("R1", "desk")]
            assert await logged(http, "fleet_sent_home") == [{"by": "desk", "robots": ["R1"]}]


async def test_doors_and_elevators_by_hand_and_every_floor_at_once(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=2) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        await web.open_view(page, "Fleet")
        floors = page.locator("figure.overview-floor")
        await expect(floors).to_have_count(2)
        await expect(page.locator('[data-floor="F0"] [data-robot="R1"]')).to_be_visible(
            timeout=20_000
        )
        await expect(page.locator('[data-floor="F0"] [data-robot="R2"]')).to_be_visible()
        await expect(page.locator('[data-floor="F1"]')).to_contain_text("0 robots")
        row = page.locator('tr[data-door-row="door_gallery"]')
        await expect(row).to_contain_text("closed", timeout=20_000)
        await row.get_by_role("button", name="Open door door_gallery").click()
        await expect(row).to_contain_text("open", timeout=20_000)
        await row.get_by_role("button", name="Close door door_gallery").click()
        await expect(row).to_contain_text("closed", timeout=20_000)
        lifts = page.get_by_role("table", name="Elevators")
        await page.get_by_label("Floor to call elevator lift to").select_option("F1")
        await lifts.get_by_role("button", name="Call elevator lift").click()
        await expect(lifts).to_contain_text("at First floor", timeout=30_000)
        await web.axe_check(page)
        await page.evaluate("window.scrollTo(0, 0)")
        await web.screenshot(page, "fleet")
        async with fleet.http(web.operator_token) as http:
            assert await logged(http, "door_opened_by_hand") == [
                {"door": "door_gallery", "by": "desk"}
            ]
            assert await logged(http, "elevator_called_by_hand") == [
                {"elevator": "lift", "floor": "F1", "by": "desk"}
            ]
            unknown = await http.post("/api/building/doors/nope/open")
            assert unknown.status_code == 404
            wrong = await http.post("/api/building/elevators/lift/call", json={"floor": "F7"})
            assert wrong.status_code == 422, wrong.text
            assert "stops at F0, F1" in wrong.json()["detail"]
        async with fleet.http("robot-R1-demo-token") as robot:  # staff only
            for path in ("/api/fleet/pause", "/api/fleet/home", "/api/building/doors/x/open"):
                assert (await robot.post(path)).status_code == 403, path


async def test_a_moving_car_is_shown_moving_not_at_the_floor_it_left(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The Fleet view said "at Ground floor" (and drew the car at its ground-floor stop) for
    the whole ride up, and so did the map: they say what the Building view says, "moving to
    First floor", and draw the car at no stop."""
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        await web.open_view(page, "Fleet")
        lifts = page.get_by_role("table", name="Elevators")
        await expect(lifts).to_contain_text("at Ground floor", timeout=20_000)
        stop = page.locator('[data-floor="F0"] rect title', has_text="elevator lift")
        await expect(stop).to_have_text("elevator lift: the car is here")
        fleet.building.elevators["lift"].floor_s = 600.0  # a ride the test outlasts
        await page.get_by_label("Floor to call elevator lift to").select_option("F1")
        await lifts.get_by_role("button", name="Call elevator lift").click()
        await expect(lifts).to_contain_text(
            "moving to First floor (last at Ground floor)", timeout=20_000
        )
        moving = "elevator lift: the car is moving to First floor (last at Ground floor)"
        await expect(stop).to_have_text(moving)  # not "here" at the floor it left
        upstairs = page.locator('[data-floor="F1"] rect title', has_text="elevator lift")
        await expect(upstairs).to_have_text(moving)
        await web.axe_check(page)
        # The map drew the car "here" at the ground floor for the whole ride.
        await web.open_view(page, "Map")
        await expect(page.locator("#map path.map-lift")).to_have_class(re.compile(r"\baway\b"))
