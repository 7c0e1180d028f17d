"""One set of site rules: the site check, the server's building check (BuildingInterface) and
the simulator accept exactly the point kinds guidebot.site.io_rules allows for each role."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from building_sim.simulator import BuildingSimulator
from guidebot.site.building_config import BuildingConfigError, load_building
from guidebot.site.io_rules import PointKind, Role, allowed
from guidebot.site.validate import SiteInvalid, validate_site

DEMO = Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml"

# role -> (module, point) it names in the demo site
ROLE_POINTS = {
    Role.door_open: ("otb_ground", "door_hall_open"),
    Role.door_is_open: ("otb_ground", "door_hall_is_open"),
    Role.elevator_call: ("otb_ground", "lift_call"),
    Role.elevator_in_position: ("otb_ground", "lift_here"),
    Role.button_input: ("otb_ground", "button_entrance"),
    Role.button_led: ("otb_ground", "led_entrance"),
}


def _with_kind(module: str, point: str, kind: PointKind) -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(DEMO.read_text())
    [m] = [m for m in data["modules"] if m["id"] == module]
    [pt] = [p for p in m["points"] if p["name"] == point]
    pt["kind"], pt["address"] = kind.value, 100  # a free address in every table
    return data


@pytest.mark.parametrize("kind", list(PointKind))
@pytest.mark.parametrize("role", list(ROLE_POINTS))
def test_every_component_applies_the_same_table(role: Role, kind: PointKind) -> None:
    module, point = ROLE_POINTS[role]
    data = _with_kind(module, point, kind)
    expected = allowed(role, kind)
    try:
        validate_site(data)
        site_ok, site_error = True, ""
    except SiteInvalid as exc:
        site_ok, site_error = False, str(exc)
    try:
        config = load_building(data)
        BuildingSimulator(config)  # what `guidebot building-sim` runs
        building_ok, building_error = True, ""
    except BuildingConfigError as exc:
        building_ok, building_error = False, str(exc)
    assert site_ok is expected, site_error
    assert building_ok is expected, building_error
    if not expected:
        why = f"{role.value} {module}/{point} is a {kind.value}; it must be a"
        assert why in site_error
        assert why.replace("/", ".") in building_error


def test_the_issue_cases() -> None:
    """A holding register as a door's open point is refused by the site check (the simulator
    refused it); a coil as is_open is accepted by both (docs/building.md allows it)."""
    assert not allowed(Role.door_open, PointKind.holding_register)
    assert allowed(Role.door_is_open, PointKind.coil)
    assert allowed(Role.output, PointKind.holding_register)
    assert not allowed(Role.output, PointKind.discrete_input)
