"""The staff console's sign-in and live map in a real browser, against a real server with
simulated robots."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(90)]


async def test_sign_in_shows_the_plan_and_live_robots(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=2) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await expect(page.get_by_role("heading", name="Sign in")).to_be_visible()
        await web.axe_check(page)
        await web.sign_in(watch, fleet.server.admin_token)
        # The plan image of the ground floor lies under the graph.
        await expect(page.locator("#map img.leaflet-image-layer")).to_have_count(1, timeout=15_000)
        # Robot markers come from robot_state messages over the hub, not from REST.
        r1 = page.get_by_role("button", name="robot R1")
        await expect(r1).to_be_visible(timeout=20_000)
        await expect(page.get_by_role("button", name="robot R2")).to_be_visible()
        await expect(page.locator("#who")).to_contain_text("admin")
        await r1.click()
        await expect(page.locator("#details")).to_contain_text("Robot R1")
        await expect(page.locator("#details")).to_contain_text("online")
        await web.axe_check(page)
        await web.screenshot(page, "map")
        drawn = await page.evaluate("guidebotProbe.takeLatencies().length")
        assert drawn > 0


async def test_wrong_token_says_why_and_stays_on_sign_in(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(fleet.admin_url)
        watch.expect_error(r"status of 401")
        await watch.page.get_by_label("Staff token").fill("not-a-token")
        await watch.page.get_by_role("button", name="Sign in").click()
        await expect(watch.page.get_by_role("alert")).to_contain_text("not accepted")
        await expect(watch.page.get_by_role("heading", name="Sign in")).to_be_visible()
        assert await watch.page.evaluate("sessionStorage.length") == 0


async def test_a_kiosk_signs_in_with_the_token_in_the_fragment(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """#token=... is never sent to the server; the page uses it and stores nothing."""
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(f"{fleet.admin_url}#token={web.operator_token}")
        await expect(watch.page.locator("#who")).to_contain_text("desk")
        await expect(watch.page.get_by_role("heading", name="Sign in")).to_be_hidden()
        assert await watch.page.evaluate("sessionStorage.getItem('guidebot.token')") is None
