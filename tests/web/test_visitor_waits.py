"""Waits on the phone tell the truth (docs/visitor.md, "The wait"), in a real browser against a
real server and a simulated robot: a robot later than foretold on its way to the first stop is
said to be on its way, with no figure, never a countdown that has run out."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from tests.web.test_visitor import (
    LONG,
    PHONE,
    SEEN,
    request_from,
    told_a_wait,
    without_task_news,
)
from tests.web.test_visitor import visitor_fleet as visitor_fleet  # the fixture

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


async def test_a_robot_late_to_the_first_stop_is_on_its_way_without_a_figure(
    visitor_fleet: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """An arrival stuck at "about 6 s" for 56 s (last session): the robot here runs at half
    the speed the first forecast assumes, so its leg to the first stop outlasts the figure
    told. The phone then says it is on its way, with no figure, until it is there."""
    async with visitor_fleet(time_scale=0.5) as vf:
        page = (await open_page(vf.panel_url(), viewport=PHONE)).page
        await request_from(page, "Ground floor tour")
        state = page.locator(".request-state")
        await expect(state).to_contain_text("R1 is on its way: at the first stop in about")
        await expect(state).to_contain_text("R1 is on its way to the first stop.", timeout=LONG)
        await expect(state).not_to_contain_text("in about")
        await web.axe_check(page)
        await expect(state).to_contain_text("R1 has arrived at Welcome hall", timeout=LONG)


async def test_a_visit_cancelled_at_its_point_says_the_robot_had_got_there(
    visitor_fleet: Any, open_page: Any
) -> None:
    """A visit's "arrived" was dropped at its end: a visitor who cancelled once the robot was
    at the point read only "Your request was cancelled." The server keeps it; the page says
    the robot had got there."""

    def long_welcome(data: dict[str, Any]) -> None:
        """A welcome of 120 words: the robot is at the point for a while (tens of seconds)."""
        welcome = next(p for p in data["pois"] if p["id"] == "welcome")
        welcome["text"] = " ".join(["Welcome to the museum."] * 30)

    async with visitor_fleet(time_scale=2.0, edit=long_welcome) as vf:
        page = (await open_page(vf.panel_url(), viewport=PHONE)).page
        await request_from(page, "Welcome hall", "Take me there")
        state = page.locator(".request-state")
        await expect(state).to_contain_text("R1 is at Welcome hall", timeout=LONG)
        await page.get_by_role("button", name="Cancel my request").click()
        await page.get_by_role("button", name="Yes, cancel it").click()
        await expect(state).to_contain_text("Your request was cancelled.", timeout=LONG)
        await expect(state).to_contain_text("R1 had reached Welcome hall.")


async def test_a_told_wait_is_shown_to_the_nearest_ten_seconds(
    visitor_fleet: Any, open_page: Any
) -> None:
    """The busy demo: told 21 s, the phone said "in about 30 s" (rounded up). The server here
    tells a wait of 24 s and nothing new after it: the page says "about 20 s", never 30."""
    async with visitor_fleet(time_scale=1.0) as vf:
        page = (await open_page("", viewport=PHONE)).page

        await without_task_news(page)
        await page.goto(vf.panel_url())
        async with vf.fleet.http() as staff:  # R1 busy: the visitor waits in line
            r = await staff.post(
                "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "telescope"}}
            )
            assert r.status_code == 201, r.text
        await told_a_wait(page, 24.0)
        await page.evaluate(SEEN)
        await request_from(page, "Highlights")
        state = page.locator(".request-state")
        await expect(state).to_contain_text("A robot will start for you in about 20 s.")
        await expect(state).to_contain_text(
            "A robot will start for you in about 10 s.", timeout=LONG
        )
        seen: list[str] = await page.evaluate("window.__seen")
        assert not [text for text in seen if "about 30 s" in text], seen
