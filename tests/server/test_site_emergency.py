"""The site's emergency part: the demo has one, and ``guidebot site check`` refuses a broken one
with file:line (issue 35)."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from guidebot.cli import main
from guidebot.site import SiteInvalid, load_site_text
from guidebot.site.emergency import nearest_safe_spot

from .helpers import DEMO, demo_site


def _refused(text: str) -> dict[str, tuple[str, int | None]]:
    with pytest.raises(SiteInvalid) as info:
        load_site_text(text)
    return {i.loc: (i.message, i.line) for i in info.value.issues}


def test_demo_site_has_an_emergency_part() -> None:
    site = demo_site()
    em = site.emergency
    assert em is not None
    assert em.alarms[0].input.module == "otb_ground" and em.alarms[0].zone.whole_site
    assert {"en", "es"} <= set(em.words)
    assert em.escape_routes == ["corridor"]


def test_nearest_safe_spot_avoids_elevators_doors_and_escape_routes() -> None:
    site = demo_site()
    assert site.emergency is not None
    # gb1 is east of the corridor (an escape route): out by the one-way back gallery
    assert nearest_safe_spot(site, site.emergency, "gb1") == ["gb1", "gb2", "ga2"]
    # inside the corridor: leave it by the shortest way
    path = nearest_safe_spot(site, site.emergency, "corridor_w")
    assert path is not None and path[-1] == "ga2"
    # the first floor's robots stay on the first floor, and do not cross door_f1 (nearer)
    assert nearest_safe_spot(site, site.emergency, "gc1") == ["gc1", "gc2", "gc3"]
    # a robot standing in a door's way leaves it
    path = nearest_safe_spot(site, site.emergency, "door_f1")
    assert path is not None and path[-1] == "landing"


def test_alarm_on_a_missing_module_is_refused_with_its_line() -> None:
    text = DEMO.read_text().replace(
        "input: {module: otb_ground, point: fire_alarm}",
        "input: {module: otb_cellar, point: fire_alarm}",
    )
    issues = _refused(text)
    message, line = issues["emergency.alarms[0].input"]
    assert "unknown building point 'otb_cellar'/'fire_alarm'" in message
    assert "otb_ground" in message  # says which modules exist
    assert line is not None and "otb_cellar" in text.splitlines()[line - 1]


def test_alarm_on_a_register_is_refused() -> None:
    text = DEMO.read_text().replace(
        "{name: fire_alarm, address: 4, kind: discrete_input,",
        "{name: fire_alarm, address: 4, kind: input_register,",
    )
    message, _ = _refused(text)["emergency.alarms[0].input"]
    assert "must be a" in message


def test_safe_spot_not_a_node_and_in_an_escape_route_are_refused() -> None:
    text = DEMO.read_text().replace(
        "safe_spots: [charge_b, ga2, landing, gc3]",
        "safe_spots: [charge_b, ga2, landing, gc3, roof, corridor_e, door_hall]",
    )
    issues = _refused(text)
    assert "is the node of door door_gallery" in issues["emergency.safe_spots[6]"][0]
    assert "'roof' is not a node" in issues["emergency.safe_spots[4]"][0]
    assert "lies in an escape route" in issues["emergency.safe_spots[5]"][0]
    assert issues["emergency.safe_spots[4]"][1] is not None


def test_floor_with_robots_and_no_safe_spot_is_refused() -> None:
    # without gc3 and landing, the first floor (a wait point, robots can be there) has none
    text = DEMO.read_text().replace(
        "safe_spots: [charge_b, ga2, landing, gc3]", "safe_spots: [charge_b, ga2]"
    )
    text = text.replace("start_node: entrance}", "start_node: gc1}")
    issues = _refused(text)
    message, line = issues["floors[1]"]
    assert "floor F1 has robots but no safe spot reachable without an elevator" in message
    assert line is not None


def test_site_check_command_names_the_file_and_line(tmp_path: Path) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text(
        DEMO.read_text().replace(
            "input: {module: otb_ground, point: fire_alarm}",
            "input: {module: otb_ground, point: smoke}",
        )
    )
    bad = CliRunner().invoke(main, ["site", "check", str(broken)])
    assert bad.exit_code == 1
    assert f"{broken}:" in bad.output and "emergency.alarms[0].input" in bad.output
