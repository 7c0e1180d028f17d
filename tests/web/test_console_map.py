"""The console's map says what is there (issue 33): robots on one node are each visible and
clickable, a robot held up by a jammed door says so (not "busy"), points of interest carry
their names, tasks and places use the site's names."""

from __future__ import annotations

import re
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


def two_robots_on_one_station(data: dict[str, Any]) -> None:
    """R1 and R2 start at station_a, the only station, and there is no wait point: nothing
    sends either of them elsewhere."""
    data["charging_stations"] = [s for s in data["charging_stations"] if s["id"] == "station_a"]
    data["wait_points"] = []
    for robot in data["robots"][:2]:
        robot["start_node"] = "charge_a"


async def test_robots_on_one_node_are_each_visible_and_clickable(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=2, edit=two_robots_on_one_station) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        r1 = page.get_by_role("button", name="robot R1")
        r2 = page.get_by_role("button", name="robot R2")
        await expect(r1).to_be_visible(timeout=20_000)
        await expect(r2).to_be_visible()
        for robot in (r1, r2):  # each one is on top where it is drawn: a click reaches it
            await robot.click()
            name = await robot.get_attribute("aria-label")
            await expect(page.locator("#details")).to_contain_text(f"Robot {name[6:]}")
        one, two = await r1.bounding_box(), await r2.bounding_box()
        assert one and two
        apart = abs(one["x"] - two["x"]) + abs(one["y"] - two["y"])
        assert apart >= 20, (one, two)
        # Points of interest are labelled on the map, by name.
        await expect(
            page.locator("#map .map-label").filter(has_text="Welcome hall")
        ).to_be_visible()
        # Places are named as the site names them.
        await expect(page.locator("#details")).to_contain_text("charging station station_a")
        await page.locator("#map path.map-poi").first.click()  # welcome, the site's first
        await expect(page.locator("#details h3")).to_have_text("Welcome hall")
        await expect(page.locator("#details")).to_contain_text("At Welcome hall (node hall)")
        await web.axe_check(page)


async def test_a_robot_held_up_by_a_jammed_door_says_so(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    def start_at_the_hall(data: dict[str, Any]) -> None:
        data["robots"][0]["start_node"] = "hall"

    async with fleet_factory(robots=1, edit=start_at_the_hall) as fleet:
        fleet.building.jam_door("door_gallery", True)
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        r1 = page.get_by_role("button", name="robot R1")
        await expect(r1).to_be_visible(timeout=20_000)
        async with fleet.http() as http:
            reply = await http.post(
                "/api/tasks", json={"kind": "go_to", "params": {"node": "ga1"}, "robot": "R1"}
            )
            assert reply.status_code == 201, reply.text
        body = r1.locator(".robot-body")
        await expect(body).to_have_class(re.compile(r"(^| )waiting( |$)"), timeout=30_000)
        await r1.click()
        await expect(page.locator("#details")).to_contain_text("door door_gallery")
        await expect(r1).to_have_attribute(
            "title", re.compile(r"R1: (waiting for|blocked:) door door_gallery")
        )
        await web.open_view(page, "Tasks")
        running = page.get_by_role("table", name="Running tasks")
        await expect(running).to_contain_text("Go to: ")
        await expect(running).not_to_contain_text(" ga1")
