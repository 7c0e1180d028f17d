"""The console's Building view against the real Modbus building simulator: where the elevator
car is, live, as it is called from floor to floor."""

from __future__ import annotations

import asyncio
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from tests.web.test_console_truth import LiveConnection

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


def without_floor_registers(data: dict[str, Any]) -> None:
    """A lift that reports only its in-position inputs (no floor or door register)."""
    for module in data["modules"]:
        module["points"] = [
            p for p in module["points"] if p["name"] not in ("lift_floor", "lift_door")
        ]


@pytest.mark.parametrize("registers", [True, False], ids=["floor-register", "inputs-only"])
async def test_the_elevator_car_shows_its_floor_and_follows_it_as_it_moves(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, registers: bool
) -> None:
    edit = None if registers else without_floor_registers
    async with fleet_factory(robots=0, edit=edit) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        await web.open_view(page, "Building")
        # Floors by their names, as everywhere in the console.
        await expect(page.get_by_role("table", name="Elevators")).to_contain_text(
            "Ground floor, First floor"
        )
        car = page.locator('[data-elevator="lift"]')
        if registers:  # the floor register says where the car stands from the start
            await expect(car).to_have_text("at Ground floor, door closed", timeout=20_000)
            async with fleet.http() as http:
                (state,) = (await http.get("/api/building")).json()["elevators"]
            assert state == {
                "elevator": "lift",
                "floor": "F0",
                "door_open": False,
                "state": "idle",
                "calls": [],
            }
        else:  # nothing says where it is until it stands somewhere with its door open
            await expect(car).to_have_text("not seen at a floor yet", timeout=20_000)

        # A ride of 60 s (6 s at the building's time scale), not the site's 12 (1.2 s): on a
        # loaded machine the building's 200 ms polls missed so short a ride (idle, then at
        # First floor), and the page rightly never said "moving".
        fleet.building.elevators["lift"].floor_s = 60.0
        endpoint = fleet.server.app.state.hub.endpoint("test")
        endpoint.publish("call_elevator", {"elevator": "lift", "floor": "F1"})
        await expect(car).to_have_attribute("data-state", "moving", timeout=20_000)
        await expect(car).to_contain_text("moving to First floor")
        await expect(car).to_have_text("at First floor, door open", timeout=20_000)
        await expect(car).to_have_text("at First floor, door closed", timeout=20_000)
        assert building_floor(fleet) == "F1"

        endpoint.publish("call_elevator", {"elevator": "lift", "floor": "F0"})
        await expect(car).to_have_text(
            "moving to Ground floor (last at First floor)", timeout=20_000
        )
        await expect(car).to_have_text("at Ground floor, door open", timeout=20_000)
        # The map's details say the same.
        await web.open_view(page, "Map")
        # A click on the car's square, off the node at its centre.
        await page.locator("#map path.map-lift").click(position={"x": 3, "y": 3})
        await expect(page.locator("#details")).to_contain_text("Car: at Ground floor")
        await web.open_view(page, "Building")
        await web.axe_check(page)


async def test_a_snapshot_fetched_before_the_lift_moved_does_not_take_its_move_back(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """A reload's snapshot answered before a car started is older than the live message that
    said so: the page keeps "moving" (CI saw a late snapshot put it back to "not seen")."""
    async with fleet_factory(robots=0, edit=without_floor_registers) as fleet:
        watch = await open_page("")
        page = watch.page
        hub = await LiveConnection.route(page)
        await page.goto(fleet.admin_url)
        await web.sign_in(watch, fleet.server.admin_token)
        await web.open_view(page, "Building")
        car = page.locator('[data-elevator="lift"]')
        await expect(car).to_have_text("not seen at a floor yet", timeout=20_000)
        fetched, release = asyncio.Event(), asyncio.Event()

        async def late_answer(route: Any) -> None:
            if fetched.is_set():  # only the reload this test holds back
                await route.continue_()
                return
            response = await route.fetch()  # the car not seen yet, as the server says now
            body = await response.json()
            # A mark the page can only have from this snapshot: a point nothing moves, "on".
            mark = next(p for p in body["points"] if not p["point"].startswith("lift"))
            mark["value"] = 1
            marked.append(f"{mark['module']}/{mark['point']}")
            fetched.set()
            await release.wait()
            await route.fulfill(response=response, json=body)

        marked: list[str] = []
        await page.route("**/api/building", late_answer)
        await hub.drop()  # the page reconnects and reloads its snapshot
        await fetched.wait()
        fleet.building.elevators["lift"].floor_s = 600.0  # a ride the test outlasts
        endpoint = fleet.server.app.state.hub.endpoint("test")
        endpoint.publish("call_elevator", {"elevator": "lift", "floor": "F1"})
        await expect(car).to_have_attribute("data-state", "moving", timeout=20_000)
        release.set()
        # The late snapshot is drawn (its mark), and the car is still on its way.
        await expect(page.locator(f'[data-point="{marked[0]}"]')).to_have_text("on")
        await expect(car).to_have_attribute("data-state", "moving")


def building_floor(fleet: Any) -> str:
    """Where the simulated car really is."""
    return str(fleet.building.elevators["lift"].floor)
