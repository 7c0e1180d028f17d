"""What the phone tells a visitor is true (docs/visitor.md), in a real browser against a real
server and simulated robots: while staff pause the fleet a request in line says so with no
countdown (a real wait again once they resume); a visit to one point says when its robot is
there; a step-free tour's card counts the stops the visitor will get."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from tests.web.test_visitor import LONG, PHONE, SEEN, request_from
from tests.web.test_visitor import visitor_fleet as visitor_fleet  # the fixture

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

PAUSED = "Staff have paused the robots for a moment"


async def test_a_request_in_line_while_staff_pause_the_fleet_says_so_without_a_wait(
    visitor_fleet: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with visitor_fleet() as vf:
        page = (await open_page(vf.panel_url(), viewport=PHONE)).page
        card = page.get_by_role("article", name="Ground floor tour")
        await expect(card).to_contain_text("A robot is free now")
        async with vf.fleet.http() as staff:
            r = await staff.post("/api/fleet/pause", json={"reason": "cleaning"})
            assert r.status_code == 200, r.text
            # The start screen follows the server live: paused, no wait offered.
            await expect(card).to_contain_text(PAUSED)
            await request_from(page, "Ground floor tour")
            state = page.locator(".request-state")
            await expect(state).to_contain_text(PAUSED)
            await expect(state).to_contain_text("You are number 1 in line")
            await expect(state).not_to_contain_text("A robot will start for you")
            await web.axe_check(page)
            r = await staff.post("/api/fleet/resume")
            assert r.status_code == 200, r.text
        await expect(state).not_to_contain_text(PAUSED)
        await expect(state).to_contain_text("R1", timeout=LONG)


async def test_a_visit_to_one_point_says_when_its_robot_is_there(
    visitor_fleet: Any, open_page: Any
) -> None:
    async with visitor_fleet() as vf:
        page = (await open_page(vf.panel_url(), viewport=PHONE)).page
        await page.evaluate(SEEN)
        await request_from(page, "Amphorae", "Take me there")
        state = page.locator(".request-state")
        await expect(state).to_contain_text("R1 has shown you Amphorae", timeout=LONG)
        seen: list[str] = await page.evaluate("window.__seen")
        at = [i for i, text in enumerate(seen) if "R1 is at Amphorae. Join it there!" in text]
        going = [i for i, text in enumerate(seen) if "R1 is going to Amphorae" in text]
        shown = [i for i, text in enumerate(seen) if "R1 has shown you Amphorae" in text]
        assert at, seen
        assert going and going[0] < at[0] < shown[0], seen


async def test_a_step_free_tours_card_counts_the_stops_the_visitor_gets(
    visitor_fleet: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with visitor_fleet() as vf:
        page = (await open_page(vf.panel_url(), viewport=PHONE)).page
        card = page.get_by_role("article", name="Ground floor tour")
        await expect(card).to_contain_text("5 stops")
        await page.get_by_role("button", name="Step-free only").click()
        await expect(card).to_contain_text("Step-free, it skips: Loom")
        await expect(card).to_contain_text("4 stops (1 not step-free)")
        await expect(card).not_to_contain_text("5 stops")
        await web.axe_check(page)


async def test_the_phone_learns_of_a_published_site_at_once(
    visitor_fleet: Any, open_page: Any
) -> None:
    """The menu was read again only on task or service news (never in a quiet museum): a
    published version now reaches the page at once (``site_published``)."""
    async with visitor_fleet() as vf:
        page = (await open_page(vf.panel_url(), viewport=PHONE)).page
        await expect(page.get_by_role("article", name="Ground floor tour")).to_be_visible()
        async with vf.fleet.http() as staff:
            draft = (await staff.get("/api/site/draft")).json()
            site = draft["draft"]
            site["tours"][0]["name"] = "Ground floor, renamed"
            saved = await staff.put(
                "/api/site/draft", json={"draft": site, "revision": draft["revision"]}
            )
            assert saved.status_code == 200, saved.text
            published = await staff.post(
                "/api/site/publish", json={"revision": saved.json()["revision"]}
            )
            assert published.status_code == 200, published.text
        await expect(page.get_by_role("article", name="Ground floor, renamed")).to_be_visible()
        await expect(page.get_by_role("article", name="Ground floor tour")).to_have_count(0)


async def test_the_touch_screen_says_staff_paused_the_fleet_in_its_language(
    visitor_fleet: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The robot's touch screen did not show the fleet's ``paused`` service: it says it, as
    the phone does, in the screen's language, and no more once staff resume. Its state line
    said "Ready" beside it: it says "Paused by staff" until they resume."""
    async with visitor_fleet() as vf:
        screen = (await open_page(vf.screen_url("R1"), viewport=(1024, 600))).page
        await expect(screen.get_by_role("heading", name="Hello, I am R1")).to_be_visible()
        async with vf.fleet.http() as staff:
            r = await staff.post("/api/fleet/pause", json={"reason": "cleaning"})
            assert r.status_code == 200, r.text
            await expect(screen.locator("#app")).to_contain_text(PAUSED, timeout=LONG)
            state = screen.locator(".touch-state")
            await expect(state).to_contain_text("Paused by staff")
            await expect(state).not_to_contain_text("Ready")
            await web.axe_check(screen)
            await web.screenshot(screen, "touch-screen-paused")
            await screen.get_by_role("button", name="Español").click()
            await expect(screen.locator("#app")).to_contain_text(
                "El personal ha pausado los robots un momento"
            )
            r = await staff.post("/api/fleet/resume")
            assert r.status_code == 200, r.text
        await expect(screen.locator("#app")).not_to_contain_text(
            "El personal ha pausado", timeout=LONG
        )
        await expect(screen.locator(".touch-state")).to_contain_text("Preparado")
