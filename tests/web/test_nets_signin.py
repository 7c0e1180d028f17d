"""People sign in on the RoboGraph editor (/nets/) with their account, as on the console
(issue 40): an author's password sign-in may publish, a viewer's reads nets without the
publishing tools; axe-core on the shared sign-in form."""

from __future__ import annotations

import re
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from backend.auth import Role
from tests.web.test_accounts import make, password_sign_in

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


async def test_an_author_signs_in_with_a_password_and_publishes(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        await make(fleet, "ann", Role.AUTHOR, "Ann the author")
        watch = await open_page(f"{fleet.server.url}/nets/")
        page = watch.page
        await expect(page.get_by_role("heading", name="Sign in")).to_be_visible()
        await web.axe_check(page)
        await password_sign_in(watch, "ann")
        await page.get_by_label("Library net").select_option("explain_point")
        await page.get_by_role("button", name="Open", exact=True).click()
        await expect(page.get_by_role("heading", name="Versions of explain_point")).to_be_visible()
        await page.get_by_label("What changed").fill("Published by a person")
        await page.get_by_role("button", name="Publish explain_point to the fleet").click()
        await expect(page.locator("#notices")).to_contain_text("explain_point version 1 published")
        versions = page.get_by_role("list", name="Versions of explain_point")
        await expect(versions).to_contain_text("Published by a person")
        assert await page.evaluate("sessionStorage.getItem('guidebot.token')") is None


async def test_a_viewer_signs_in_and_reads_nets_without_publishing(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        await make(fleet, "vic", Role.VIEWER)
        watch = await open_page(f"{fleet.server.url}/nets/")
        page = watch.page
        await password_sign_in(watch, "vic")
        await page.get_by_label("Library net").select_option("give_tour")
        await page.get_by_role("button", name="Open", exact=True).click()
        await expect(page.locator("#canvas g.net-node").first).to_be_visible()
        await expect(page.get_by_text("Read only: your role may not publish nets.")).to_be_visible()
        await expect(page.get_by_role("heading", name="Versions of give_tour")).to_be_visible()
        await expect(page.get_by_role("button", name=re.compile("^Publish"))).to_have_count(0)
        await expect(page.get_by_label("Add place")).to_have_count(0)
        await web.axe_check(page)
