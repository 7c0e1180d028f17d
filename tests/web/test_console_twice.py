"""A person may have the console open twice (issue 43): two console pages and the site editor
signed in with one admin token stay live side by side while a tour runs to its end (half a
minute or more, across several hub heartbeats: 5 s, time-out 15 s); none is thrown back to
the sign-in form, and the event log still names the person who acted."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(300)]


def short_tour(data: dict[str, Any]) -> None:
    data["tours"].append({"id": "short", "name": "Short tour", "points": ["welcome", "mosaics"]})


async def test_two_consoles_and_the_site_editor_stay_live_together(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1, time_scale=2, edit=short_tour) as fleet:
        consoles = []
        for _ in range(2):
            watch = await open_page(fleet.admin_url)
            await web.sign_in(watch, fleet.server.admin_token)
            await expect(watch.page.get_by_role("button", name="robot R1")).to_be_visible(
                timeout=20_000
            )
            consoles.append(watch.page)
        editor = (await open_page(f"{fleet.server.url}/config/")).page
        await editor.get_by_label("Admin token").fill(fleet.server.admin_token)
        await editor.get_by_label("Admin token").press("Enter")
        await editor.get_by_label("Floor", exact=True).wait_for()
        pages = [*consoles, editor]
        for page in pages:
            await expect(page.locator("#connection")).to_have_attribute("data-status", "open")
        names = [n for n in fleet.server.app.state.hub.bus.remote if n.startswith("admin")]
        assert len(names) == 3 and len(set(names)) == 3, names

        # The first console requests a tour; both consoles follow it live to its end.
        await web.open_view(consoles[0], "Tasks")
        await consoles[0].get_by_label("Target").select_option("short")
        await consoles[0].get_by_role("button", name="Request task").click()
        for page in consoles[1:]:
            await web.open_view(page, "Tasks")
        for page in consoles:
            finished = page.get_by_role("table", name="Finished tasks")
            await expect(
                finished.get_by_role("row").filter(has_text="Tour: Short tour")
            ).to_contain_text("done", timeout=150_000)
        # All three pages are still signed in and live: none was replaced by another.
        for page in pages:
            await expect(page.locator("#connection")).to_have_attribute("data-status", "open")
            await expect(page.get_by_role("button", name="Sign in")).to_have_count(0)
        # The event log names the person (the token's name), not one page's hub name.
        async with fleet.http() as http:
            events = (await http.get("/api/events", params={"limit": 500})).json()
        created = [e["data"] for e in events["events"] if e["kind"] == "task_created"]
        assert created and created[0]["requester"] == "admin", created
