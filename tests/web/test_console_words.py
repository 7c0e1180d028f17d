"""The console says one thing one way, in the words staff know, in a real browser against a
real server: the event log names floors as the other views do ("First floor", not "F1"); a
door no sensor reading has reached says "not read yet" on every view; every time is the
venue's (GUIDEBOT_TIMEZONE), labelled, whatever the browser's zone, shown and typed in."""

from __future__ import annotations

import datetime as dt
from types import SimpleNamespace
from typing import Any
from zoneinfo import ZoneInfo

import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

VENUE = "Pacific/Auckland"
BROWSER = "America/New_York"
"""Sixteen or eighteen hours apart: a time shown in the wrong one is another time of day."""


async def test_the_event_log_names_floors(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        async with fleet.http(web.operator_token) as http:
            reply = await http.post("/api/building/elevators/lift/call", json={"floor": "F1"})
            assert reply.status_code == 202, reply.text
        await web.open_view(page, "Event log")
        row = page.get_by_role("row").filter(has_text="elevator_called_by_hand")
        await expect(row).to_contain_text("floor=First floor", timeout=20_000)
        await expect(row).not_to_contain_text("floor=F1")


async def test_a_door_not_read_yet_says_so_on_every_view(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The building interface is off: no door's sensor is read. The Building view said
    "unknown", the Fleet view "not read yet", the map drew the door red and "closed"."""
    async with fleet_factory(robots=0, building_enabled=False) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        door = page.locator("#map path.map-door").first
        await expect(door).to_have_class("map-door unknown leaflet-interactive", timeout=20_000)
        await door.click()
        await expect(page.locator("#details")).to_contain_text("State: not read yet")
        await web.open_view(page, "Building")
        await expect(page.locator('[data-door="door_gallery"]')).to_have_text("not read yet")
        await web.open_view(page, "Fleet")
        row = page.locator('[data-door-row="door_gallery"]')
        await expect(row.get_by_role("cell").nth(2)).to_have_text("not read yet")
        await expect(page.locator('[data-floor="F0"] rect title').first).to_contain_text(
            "not read yet"
        )


async def test_every_time_is_the_venues_named_in_the_header(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """A browser in New York watching a venue in Auckland: an alert's time, a closure typed in
    and the reports' day are the venue's, as the bookings always were, and the header names
    the zone (the console mixed the two: bookings in the venue's zone, the rest in the
    browser's)."""
    async with fleet_factory(robots=0, timezone=VENUE) as fleet:
        watch = await open_page("")
        page = watch.page
        cdp = await page.context.new_cdp_session(page)
        await cdp.send("Emulation.setTimezoneOverride", {"timezoneId": BROWSER})
        await page.goto(fleet.admin_url)
        await web.sign_in(watch, web.operator_token)
        header = page.locator("#venue-clock")
        await expect(header).to_contain_text(f"({VENUE})")
        alert = fleet.server.app.state.alerts.raise_(
            "task_failed", "t1", "a tour failed", "warning"
        )
        shown = await page.evaluate(
            "([at, zone]) => new Date(at * 1000)"
            ".toLocaleTimeString(undefined, {timeZone: zone, hourCycle: 'h23'})",
            [alert.raised_at, VENUE],
        )
        elsewhere = await page.evaluate(
            "at => new Date(at * 1000).toLocaleTimeString()", alert.raised_at
        )
        assert shown != elsewhere
        await web.open_view(page, "Alerts")
        row = page.locator(f'[data-alert="{alert.id}"]')
        await expect(row.get_by_role("cell").first).to_have_text(shown)
        # A closure typed in for 14:00 tomorrow is 14:00 at the venue.
        tomorrow = dt.datetime.now(ZoneInfo(VENUE)).date() + dt.timedelta(days=1)
        start = dt.datetime.combine(tomorrow, dt.time(14, 0), ZoneInfo(VENUE))
        await web.open_view(page, "Modes")
        form = page.locator("form.close-form")
        await form.get_by_label("Why").fill("cleaning")
        await form.get_by_label("From").fill(f"{tomorrow.isoformat()}T14:00")
        await form.get_by_label("Until").fill(f"{tomorrow.isoformat()}T16:00")
        await form.get_by_role("button", name="Close it").click()
        await expect(page.get_by_role("status").filter(has_text="Close: done")).to_be_visible()
        async with fleet.http() as http:
            closures = (await http.get("/api/closures")).json()["closures"]
        assert [c["start"] for c in closures] == [start.timestamp()]
        assert [c["end"] for c in closures] == [start.timestamp() + 7200]
        # The reports' day is the venue's, asked in its zone.
        async with page.expect_request(lambda r: "/api/reports?" in r.url) as asked:
            await web.open_view(page, "Reports")
        url = (await asked.value).url
        assert "tz=Pacific%2FAuckland" in url
        today = dt.datetime.now(ZoneInfo(VENUE)).date().isoformat()
        assert f"day={today}" in url
        await web.axe_check(page)
