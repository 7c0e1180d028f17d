"""A site whose building part cannot work is refused before anything connects."""

from __future__ import annotations

import copy
from typing import Any

import pytest

from backend.building.filter import InputFilter
from backend.building.interface import BuildingInterface
from guidebot.bus import Bus
from guidebot.site.building_config import BuildingConfigError, load_building

from .conftest import site_dict


def broken(change: Any) -> dict[str, Any]:
    site = copy.deepcopy(site_dict())
    change(site["building"])
    return site


def test_the_test_site_is_sound() -> None:
    config = load_building(site_dict())
    assert [m.id for m in config.modules] == ["M1", "M2"]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            lambda b: b["modules"][0]["points"][0].update(address=70000),
            "at modules.0.points.0.address: Input should be less than or equal to 65535",
        ),
        (
            lambda b: b["modules"][1]["points"].append(
                {"name": "b3", "address": 0, "kind": "discrete_input"}
            ),
            "module 'M2': point 'b3' has address 0, already used by 'b2' (discrete_input)",
        ),
        (
            lambda b: b["doors"][0]["open"].update(point="d1_open"),
            "door 'D1': door open M1.d1_open is a discrete_input; it must be a coil",
        ),
        (
            lambda b: b["buttons"][0]["input"].update(module="M9"),
            "button 'B1': input names unknown module 'M9'",
        ),
        (
            lambda b: b["elevators"][0]["stops"][1]["in_position"].update(point="nope"),
            "elevator 'E1' floor '1': in_position names unknown point 'nope' of module 'M1'",
        ),
        (
            lambda b: b["modules"].append(copy.deepcopy(b["modules"][0])),
            "module 'M1' is defined twice",
        ),
        (
            lambda b: b["modules"][0].update(kind="otb"),
            "at modules.0.kind: Extra inputs are not permitted",
        ),
    ],
)
def test_bad_building_is_refused_with_a_clear_error(change: Any, message: str) -> None:
    with pytest.raises(BuildingConfigError) as info:
        load_building(broken(change))
    assert message in str(info.value)


def test_interface_refuses_a_bad_building_too() -> None:
    config = load_building(site_dict())
    bad = config.model_copy(deep=True)
    bad.doors[0].open.point = "b1"
    with pytest.raises(BuildingConfigError, match="it must be a coil"):
        BuildingInterface(Bus().endpoint("building"), bad)


def test_filter_counts_a_press_only_after_it_held() -> None:
    f = InputFilter(0.2)
    assert f.update(1, 0.00) is None
    assert f.update(1, 0.10) is None
    assert f.update(1, 0.20) == 1  # held 200 ms: counts
    assert f.update(1, 0.25) is None  # no repeat while held
    assert f.update(0, 0.30) == 0  # release counts at once


def test_filter_times_the_alarm_of_a_normally_closed_contact() -> None:
    """A fire alarm wired to a relay's normally-closed contact alarms at 0: that is the value
    that must hold (a one-sample drop of the contact is no alarm); the way back counts at once."""
    f = InputFilter(0.05, 1, active=0)
    assert f.update(0, 0.00) is None
    assert f.update(1, 0.02) is None  # a glitch: never counted
    assert f.update(0, 0.10) is None
    assert f.update(0, 0.15) == 0  # held 50 ms: the alarm
    assert f.update(1, 0.20) == 1  # the contact closes again: at once


def test_filter_drops_a_short_pulse_and_restarts_its_clock() -> None:
    f = InputFilter(0.2)
    assert f.update(1, 0.0) is None
    assert f.update(0, 0.1) is None  # 100 ms pulse: never counted, nothing to release
    assert f.update(1, 0.2) is None
    assert f.update(1, 0.35) is None  # only 150 ms since the new start
    assert f.update(1, 0.40) == 1
    with pytest.raises(ValueError, match="filter must be >= 0"):
        InputFilter(-1)
