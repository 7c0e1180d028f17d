"""The console's alerts in a real browser against a real server: robots (hub clients with the
demo robots' tokens) dropping without a goodbye and coming back. An alert resolves itself in
the console when its cause goes away, one alert per cause (counted), "Acknowledge all", and an
acknowledged alert stays acknowledged while its cause persists (docs/console.md, "Alerts")."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from backend.settings import Settings
from backend.testing import running_server
from guidebot.client import HubClient

DEMO_SITE = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"
pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


async def test_alerts_resolve_themselves_in_the_console_and_acknowledge_all(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    settings = Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", site=DEMO_SITE, building_enabled=False
    )
    async with running_server(settings) as server:
        watch = await open_page(f"{server.url}/admin/")
        page = watch.page
        await web.sign_in(watch, server.admin_token)
        bar = page.locator("#alert-bar")

        def robot(name: str) -> HubClient:
            return HubClient(server.ws_url, f"robot-{name}-demo-token")

        # Two robots drop without a word (no robot_state "offline" first): lost.
        for name in ("R1", "R2"):
            async with robot(name):
                pass
        await expect(bar).to_contain_text("2 open alerts")
        await web.open_view(page, "Alerts")
        r1 = page.get_by_role("row").filter(has_text="robot R1 lost its connection")
        r2 = page.get_by_role("row").filter(has_text="robot R2 lost its connection")
        await expect(r1).to_contain_text("open")
        await page.get_by_role("button", name="Acknowledge all (2)").click()
        await expect(bar).to_be_hidden()
        await expect(r1).to_contain_text("acknowledged by admin at")
        await expect(r2).to_contain_text("acknowledged by admin at")
        assert (await page.title()) == "GuideBot console"
        await web.axe_check(page)

        # R2 comes back: its alert resolves itself, nobody has to clear it.
        async with robot("R2"):
            await expect(r2).to_have_attribute("data-state", "resolved")
            await expect(r2).to_contain_text("robot R2 is back online")
            await expect(r1).to_have_attribute("data-state", "acknowledged")
            # R1 comes back and drops again: the same alert, open again, counted.
            async with robot("R1"):
                await expect(r1).to_have_attribute("data-state", "resolved")
            await expect(bar).to_contain_text("1 open alert: robot R1 lost its connection")
            await expect(bar).to_contain_text("2 times")
            await expect(page.get_by_role("row").filter(has_text="R1 lost")).to_have_count(1)
            # Back once more while the page shows the red bar: it goes away by itself.
            async with robot("R1"):
                await expect(bar).to_be_hidden()
                await expect(r1).to_have_attribute("data-state", "resolved")
                assert (await page.title()) == "GuideBot console"
                await web.screenshot(page, "alerts-resolved")
