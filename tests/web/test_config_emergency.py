"""The site editor's fire alarm part (issue 35): the demo museum's alarm input, safe spots and
escape route drawn and edited in a real browser against a real server, a safe spot put in the
escape route refused with its problem, and the edit published."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from tests.web.test_config import open_editor

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


async def _draft(fleet: Any) -> dict[str, Any]:
    async with fleet.http() as http:
        draft: dict[str, Any] = (await http.get("/api/site/draft")).json()["draft"]
    return draft


async def test_the_fire_alarm_part_is_drawn_edited_checked_and_published(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        watch = await open_editor(open_page, fleet)
        page = watch.page
        await page.get_by_role("button", name="Fire alarm (1 input)").click()
        form = page.locator("section.emergency")
        alarm = form.get_by_role("group", name="Alarm fire_main")
        await expect(alarm.get_by_label("input", exact=True)).to_have_value("otb_ground/fire_alarm")
        await expect(alarm.get_by_label("zone", exact=True)).to_have_value("site")
        await expect(form.get_by_label("corridor")).to_be_checked()
        await expect(page.locator("#alarm-zones")).to_have_text(
            "Alarm inputs covering this floor (configuration, not a live alarm): "
            "fire_main (whole site)"
        )
        # On the ground floor's plan: the corridor drawn as an escape route, its safe spots.
        await expect(page.locator("path.map-escape")).to_have_count(1)
        for spot in ("charge_b", "ga2"):
            await expect(page.get_by_title(f"safe spot {spot}")).to_be_visible()
        await web.axe_check(page)
        await web.screenshot(page, "config-emergency")

        # The "Safe spot" tool: a node clicked on the plan becomes one; one in the escape
        # route is a problem, shown on the form, and publishing is refused.
        watch.expect_error(r"status of 422")
        await page.get_by_label("Safe spot", exact=True).check()
        await page.get_by_title("node corridor_w", exact=True).click()
        await expect(page.get_by_title("safe spot corridor_w")).to_be_visible()
        await expect(form.get_by_role("alert")).to_contain_text(
            "safe spot 'corridor_w' lies in an escape route"
        )
        await expect(page.locator("#problem-count")).to_contain_text("publishing is refused")
        await form.get_by_role("button", name="Remove safe spot corridor_w").click()
        await expect(page.locator("#problem-count")).to_have_text("No problems")
        await page.get_by_title("node hall", exact=True).click()
        await expect(page.get_by_title("safe spot hall")).to_be_visible()

        # The alarm's zone becomes the first floor, its contact normally-closed, and the
        # Spanish words change.
        await alarm.get_by_label("zone", exact=True).select_option("floors")
        floors = alarm.get_by_role("group", name="Floors of the zone")
        await floors.get_by_label("First floor").check()
        await floors.get_by_label("Ground floor").uncheck()
        await alarm.get_by_label("alarm when the input reads").select_option("0")
        words = form.get_by_label("es", exact=True)
        await words.fill("Alarma de incendio. Salgan por las salidas verdes.")
        await words.press("Tab")
        await page.evaluate("guidebotProbe.saved()")
        await expect(page.locator("#problem-count")).to_have_text("No problems")
        em = (await _draft(fleet))["emergency"]
        assert "hall" in em["safe_spots"] and "corridor_w" not in em["safe_spots"]
        assert em["alarms"][0]["zone"] == {"floors": ["F1"]}
        assert em["alarms"][0]["active_when"] == 0
        assert em["words"]["es"] == "Alarma de incendio. Salgan por las salidas verdes."
        # Only the first floor's plan says it is in the alarm's zone now.
        await expect(page.locator("#alarm-zones")).to_have_count(0)
        await web.axe_check(page)

        await page.get_by_role("button", name="Publish", exact=True).click()
        await expect(page.get_by_role("status").filter(has_text="is live").first).to_be_visible()
        async with fleet.http() as http:
            live = (await http.get("/api/site")).json()["site"]["emergency"]
        assert live["alarms"][0]["zone"]["floors"] == ["F1"] and "hall" in live["safe_spots"]
