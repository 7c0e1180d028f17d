"""The fire alarm on the staff console, in a real browser against a real server, the Modbus
building simulator and a simulated robot (docs/emergency.md, docs/console.md "Fire alarm"):
the alarm input raised from the Building view brings the banner (zone, since, who), the alert
and each robot's evacuation; "Resume service" is refused with the server's reason while the
input still reads alarm, and works once it is cleared; "Declare emergency" asks first."""

from __future__ import annotations

import re
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

LONG = 30_000


async def test_the_alarm_input_brings_the_banner_and_resume_is_refused_until_it_is_reset(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        watch.expect_error(r"status of 409")  # the refused resume: part of the scenario
        await web.sign_in(watch, web.operator_token)
        banner = page.locator("#emergency-banner")
        await expect(
            page.get_by_role("button", name="Declare emergency", exact=True)
        ).to_be_visible()
        await expect(banner).to_be_hidden()
        await web.open_view(page, "Building")
        await expect(page.locator("#emergency-state")).to_contain_text("normal")
        reads = page.locator('[data-alarm-input="fire_main"]')
        await expect(reads).to_have_text("normal", timeout=LONG)

        await page.get_by_role("button", name="Raise alarm fire_main").click()
        await expect(banner).to_be_visible(timeout=LONG)
        await expect(banner.get_by_role("heading")).to_have_text("Fire alarm: the whole site")
        await expect(banner).to_contain_text("declared by the building's alarm input fire_main")
        await expect(banner).to_contain_text("fire_main (otb_ground/fire_alarm) reads alarm")
        await expect(reads).to_have_text("alarm")
        # The robot's evacuation, as it reports it: it reaches its safe spot.
        await expect(banner.locator('[data-evacuation="R1"]')).to_have_attribute(
            "data-state", "safe", timeout=LONG
        )
        await expect(banner.locator('[data-evacuation="R1"]')).to_contain_text("R1: safe at")
        # Staff are alerted as for any other alert; the header no longer offers to declare.
        bar = page.locator("#alert-bar")
        await expect(bar).to_contain_text("Fire alarm: the whole site (declared by alarm input")
        await expect(
            page.get_by_role("button", name="Declare emergency", exact=True)
        ).to_have_count(0)
        await web.axe_check(page)
        await web.screenshot(page, "console-fire-alarm")

        # Resume while the input still reads alarm: refused, the server's reason shown.
        await banner.get_by_role("button", name="Resume service").click()
        refusal = banner.get_by_role("alert")
        await expect(refusal).to_contain_text(
            "Resume service refused: alarm input fire_main (otb_ground/fire_alarm) still reads"
            " alarm: resume once the building's alarm is reset"
        )
        async with fleet.http() as http:
            assert (await http.get("/api/emergency")).json()["state"] == "alarm"

        # The alert is acknowledged like any other.
        await bar.get_by_role("button", name="Acknowledge").click()
        await expect(bar).to_be_hidden()

        # The building's alarm is reset: nothing restarts until a person resumes.
        await page.get_by_role("button", name="Clear alarm fire_main").click()
        await expect(banner).to_contain_text("alarm input normal", timeout=LONG)
        await expect(banner).to_contain_text("until a person resumes service")
        await expect(refusal).to_have_count(0)
        await banner.get_by_role("button", name="Resume service").click()
        await expect(banner).to_be_hidden(timeout=LONG)
        await expect(page.locator(".notice.ok")).to_contain_text("Resume service: done.")
        await expect(page.locator("#emergency-state")).to_contain_text("normal")
        await expect(
            page.get_by_role("button", name="Declare emergency", exact=True)
        ).to_be_visible()
        await web.open_view(page, "Alerts")
        row = page.get_by_role("row").filter(has_text="Fire alarm: the whole site")
        await expect(row).to_have_attribute("data-state", "resolved")
        await expect(row).to_contain_text("service resumed after the fire alarm")


async def test_declare_emergency_asks_first_then_holds_the_site_until_resumed(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        banner = page.locator("#emergency-banner")
        declare = page.get_by_role("button", name="Declare emergency", exact=True)

        # The confirmation keeps things as they are unless the person chooses to declare.
        await declare.click()
        dialog = page.get_by_role("dialog", name="Declare a fire alarm for the whole site?")
        await expect(dialog).to_be_visible()
        await expect(dialog.get_by_role("button", name="Do not declare")).to_be_focused()
        await web.axe_check(page)
        await web.screenshot(page, "console-declare-emergency")
        await dialog.get_by_role("button", name="Do not declare").click()
        await expect(dialog).to_have_count(0)
        await expect(banner).to_be_hidden()
        async with fleet.http() as http:
            assert (await http.get("/api/emergency")).json()["state"] == "normal"

        await declare.click()
        await dialog.get_by_role("button", name="Declare emergency", exact=True).click()
        await expect(banner).to_be_visible()
        await expect(banner).to_contain_text("declared by desk (declared from the console by desk)")
        # Each robot's evacuation in the Robots view and on the map's details.
        await web.open_view(page, "Robots")
        evacuation = page.locator('dd[data-evacuation="R1"]')
        await expect(evacuation).to_have_text("safe at charging station station_b", timeout=LONG)
        await web.open_view(page, "Map")
        # The element, not a point: a moving marker (or one moved aside) can be missed.
        await page.get_by_role("button", name="robot R1").dispatch_event("click")
        await expect(page.locator("#details")).to_contain_text("Evacuation")
        await expect(page.locator("#details")).to_contain_text("safe at")
        # The marker's ring says it too: green, double, while the alarm holds.
        ring = page.locator('[aria-label="robot R1"] .robot-body')
        await expect(ring).to_have_class(re.compile(r"\bevac-safe\b"))
        await expect(ring).to_have_css("border-color", "rgb(27, 122, 58)")
        await expect(ring).to_have_css("border-top-style", "double")
        await expect(page.locator("#map-toolbar")).to_contain_text("fire alarm, double ring")
        await web.axe_check(page)

        # Declared by a person, no input reads alarm: resumed in one step.
        await banner.get_by_role("button", name="Resume service").click()
        await expect(banner).to_be_hidden(timeout=LONG)
        await expect(page.locator("#details")).not_to_contain_text("Evacuation")
        await expect(ring).not_to_have_class(re.compile(r"\bevac\b"))
        async with fleet.http() as http:
            state = (await http.get("/api/emergency")).json()
        assert state["state"] == "normal"
        async with fleet.http() as http:
            rows = (await http.get("/api/events?kind=emergency_declared")).json()["events"]
        assert rows[-1]["data"]["by"] == "desk"
