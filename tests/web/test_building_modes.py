"""Building modes in a real browser against a real server, the building simulator and a
simulated robot: staff close a gallery from the console (shown in the list and on the map, in
the event log with who did it); a visitor's tour skips the stop it cuts off, the visitor panel
says which stop and why, and the tour goes on to its end."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from guidebot.site.schema import Site
from robot_agent.testing import light_robot

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

PANEL = "panel-modes-token"
LONG = 60_000
TIME_SCALE = 40.0


async def test_a_closed_gallery_is_skipped_by_a_tour_and_the_visitor_is_told(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Site
) -> None:
    robot = demo_site.robots[0]
    async with (
        fleet_factory(robots=0) as fleet,
        light_robot(
            fleet.server.url,
            robot.name,
            robot.token,
            site=fleet.site_file,
            start_node=robot.start_node,
            time_scale=TIME_SCALE,
        ) as agent,
    ):
        fleet.server.app.state.tokens.add(PANEL, "panel-modes", "panel")
        reached: list[str] = []
        agent.bus.endpoint("test-nodes").subscribe(
            "node_reached", lambda m: reached.append(m.payload["node"]), tap=True
        )
        console = await open_page(fleet.admin_url)
        page = console.page
        await web.sign_in(console, web.operator_token)
        await web.open_view(page, "Modes")
        await expect(page.get_by_role("cell", name="Nothing is closed.")).to_be_visible()
        # The Bronze Age gallery (gb1, gb2) is closed for cleaning.
        await page.locator('select[name="kind"]').select_option("nodes")
        await page.get_by_role("textbox", name="Nodes").fill("gb1, gb2")
        await page.get_by_label("Why").fill("Cleaning")
        await page.get_by_role("button", name="Close it").click()
        row = page.get_by_role("row", name="nodes gb1, gb2")
        await expect(row).to_contain_text("Cleaning")
        await expect(row).to_contain_text("closed now")
        await expect(row).to_contain_text("desk")
        await web.axe_check(page)
        await web.screenshot(page, "console-building-modes")
        await web.open_view(page, "Map")
        await expect(page.locator("path.map-closed")).to_have_count(2)
        async with fleet.http() as staff:
            events = (await staff.get("/api/events?kind=closure_added")).json()["events"]
        assert [(e["data"]["what"], e["data"]["by"]) for e in events] == [
            ("nodes gb1, gb2", "desk")
        ]

        visitor = await open_page(f"{fleet.server.url}/visitor/#token={PANEL}")
        panel = visitor.page
        assert agent.screen_server is not None
        screen = (await open_page(agent.screen_server.url, viewport=(1024, 600))).page
        card = panel.get_by_role("article", name="Highlights")
        await card.get_by_role("button", name="Take this tour").click()
        skipped = panel.locator(".skipped")
        await expect(skipped).to_contain_text("Stops skipped", timeout=LONG)
        await expect(skipped).to_contain_text(
            "Stop 2, Bronze Age sword: that part of the museum is closed (Cleaning)"
        )
        # The robot's touch screen lists it too.
        await expect(screen.locator(".skipped")).to_contain_text(
            "Stop 2, Bronze Age sword: that part of the museum is closed (Cleaning)", timeout=LONG
        )
        state = panel.locator(".request-state")
        await expect(state).to_contain_text("The tour has ended", timeout=LONG)
        await expect(skipped).to_be_visible()  # still said once the tour is over
        await web.axe_check(panel)
        await web.screenshot(panel, "visitor-stop-skipped")
        # The robot showed the two open stops and never went into the closed gallery.
        assert {"ga1", "gc2"} <= set(reached) and not set(reached) & {"gb1", "gb2"}
