"""The console's Building view against the real Modbus building simulator: where the elevator
car is, live, as it is called from floor to floor."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

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


def building_floor(fleet: Any) -> str:
    """Where the simulated car really is."""
    return str(fleet.building.elevators["lift"].floor)
