"""The console at the screen sizes of a front desk (1280x800) and a control room (1920x1080),
in a real browser against a real server: the tabs in one row, even with the alert count; a
selected robot that is lost says so in the map's details (connection lost, mode offline), as the
Robots view does."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

TAB_ROWS = (
    "() => new Set([...document.querySelectorAll('#tabs button')].map((b) => b.offsetTop)).size"
)


@pytest.mark.parametrize("size", [(1280, 800), (1920, 1080)], ids=["1280x800", "1920x1080"])
async def test_a_lost_robot_raises_the_count_and_the_tabs_stay_in_one_row(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, size: tuple[int, int]
) -> None:
    """An admin (every tab, Accounts too) with an open alert (its count on the Alerts tab):
    at 1280x800 "Accounts" went to a second row, taking the map's height."""
    async with fleet_factory(robots=1) as fleet:
        watch = await open_page(fleet.admin_url, viewport=size)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        marker = page.get_by_role("button", name="robot R1")
        await expect(marker).to_be_visible(timeout=20_000)
        await marker.dispatch_event("click")  # not at a point: see test_console_viewer
        details = page.locator("#details")
        await expect(details).to_contain_text("Robot R1")
        await fleet.kill("R1")
        count = page.locator("#tabs").get_by_role("button", name="Alerts")
        await expect(count).to_contain_text("1", timeout=20_000)
        assert await page.evaluate(TAB_ROWS) == 1
        # Its last state said "idle": the details say what the Robots view says.
        connection = details.locator("dt", has_text="Connection")
        await expect(connection.locator("xpath=following-sibling::dd[1]")).to_have_text("lost")
        mode = details.locator("dt", has_text="Mode").locator("xpath=following-sibling::dd[1]")
        await expect(mode).to_have_text("offline")
        await web.axe_check(page)


async def test_a_door_is_drawn_above_the_points_labels(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The "Welcome hall" label (a fixed size on screen) lay over door_gallery when the map
    was zoomed out or the robots pushed it there: its red or green could not be seen. Doors are
    drawn above the labels, wherever the labels go."""
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        door = page.locator("#map path.map-door").first
        await expect(door).to_be_visible(timeout=20_000)
        await expect(page.locator("#map .map-label", has_text="Welcome hall")).to_be_visible()
        # Leaflet's labels let clicks through (elementFromPoint passes them by): what is
        # drawn on top is the pane higher in the stack.
        stacked = await page.evaluate(
            """() => {
              const pane = (el) => Number(getComputedStyle(el.closest('.leaflet-pane')).zIndex);
              const label = [...document.querySelectorAll('#map .map-label')]
                .find((l) => l.textContent.includes('Welcome hall'));
              return [pane(document.querySelector('#map path.map-door')), pane(label)];
            }"""
        )
        assert stacked[0] > stacked[1], stacked
