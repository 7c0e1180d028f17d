"""A viewer's console (issue 40, rule ``watch``): it signs in with its password and sees the
map, the robots and the tasks, and no button that changes anything; the server refuses a
viewer's change (403) as docs/server.md says."""

from __future__ import annotations

import re
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from backend.auth import Role
from tests.web.test_accounts import make, password_sign_in

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

CHANGES = re.compile(
    r"^(Cancel|Declare emergency|Pause|Resume|Acknowledge|Send|Request task|Set priority"
    r"|Reassign|Force release|Open |Close|Call |Press |Raise alarm)"
)
"""The names of the console's buttons that change something."""


async def test_a_viewer_watches_the_console_and_changes_nothing(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        await make(fleet, "vic", Role.VIEWER, "Victoria, front desk")
        async with fleet.http() as http:  # the admin: a paused fleet keeps a task queued
            assert (await http.post("/api/fleet/pause", json={})).status_code == 200
            reply = await http.post(
                "/api/tasks", json={"kind": "tour", "params": {"tour": "ground"}}
            )
            assert reply.status_code == 201, reply.text
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await password_sign_in(watch, "vic")
        await page.get_by_label("Floor", exact=True).wait_for()
        await expect(page.locator("#who")).to_contain_text("Victoria, front desk")
        await expect(page.locator("#read-only")).to_contain_text("Read only")
        r1 = page.get_by_role("button", name="robot R1")
        await expect(r1).to_be_visible(timeout=20_000)
        # A click on the element itself: a click at a point can miss a marker that the next
        # robot's first report moves aside (markers at one node are spread; CI saw it miss).
        await r1.dispatch_event("click")
        await expect(page.locator("#details")).to_contain_text("Robot R1")
        await expect(page.get_by_role("button", name="Declare emergency")).to_have_count(0)
        await expect(page.locator("#details").get_by_role("button")).to_have_count(0)
        await web.open_view(page, "Tasks")
        queued = page.get_by_role("table", name="Queued tasks")
        await expect(queued.get_by_role("row")).to_have_count(2)
        await expect(page.get_by_role("button", name="History")).to_be_visible()
        await expect(page.get_by_role("button", name=re.compile("^Cancel"))).to_have_count(0)
        await web.open_view(page, "Robots")
        await expect(page.locator("#view")).to_contain_text("R1")
        for view in ("Robots", "Fleet", "Locks", "Building", "Modes", "Bookings", "Alerts"):
            await web.open_view(page, view)
            await expect(page.locator("#view h2").first).to_be_visible()
            await expect(page.locator("#view").get_by_role("button", name=CHANGES)).to_have_count(0)
        await web.open_view(page, "Fleet")
        await expect(page.locator("#fleet-state")).to_contain_text("paused")
        await web.axe_check(page)
        # The page's own session cookie and CSRF token: refused for the role, not the request.
        signed_in = await (await page.request.get(f"{fleet.server.url}/api/session")).json()
        refused = await page.request.post(
            f"{fleet.server.url}/api/fleet/resume",
            data={},
            headers={"X-CSRF-Token": signed_in["csrf"]},
        )
        assert refused.status == 403
        fleet_now = await (await page.request.get(f"{fleet.server.url}/api/fleet")).json()
        assert fleet_now["paused"] is True
