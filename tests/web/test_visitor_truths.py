"""What the phone tells a visitor is true (docs/visitor.md), in a real browser against a real
server and simulated robots: while staff pause the fleet a request in line says so with no
countdown (a real wait again once they resume); a visit to one point says when its robot is
there; a step-free tour's card counts the stops the visitor will get."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from tests.web.test_visitor import LONG, PHONE, request_from
from tests.web.test_visitor import visitor_fleet as visitor_fleet  # the fixture

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

PAUSED = "Staff have paused the robots for a moment"

SEEN = """
window.__seen = [];
new MutationObserver(() => {
  for (const el of document.querySelectorAll(".request-state")) {
    const text = el.textContent.replace(/\\s+/g, " ").trim();
    if (text && window.__seen.at(-1) !== text) window.__seen.push(text);
  }
}).observe(document, { subtree: true, childList: true, characterData: true });
"""
"""Every text the request's state showed, in order (a short-lived one too)."""


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
