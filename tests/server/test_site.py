"""The site file: the demo loads, round-trips, and a broken file is refused with every error."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from guidebot.cli import main
from guidebot.site import SiteInvalid, dump_site, load_site_text

from .helpers import DEMO, demo_site


def test_demo_site_has_what_the_issue_asks_for() -> None:
    site = demo_site()
    assert len(site.floors) == 2
    assert len(site.elevators) == 1 and {s.floor for s in site.elevators[0].stops} == {"F0", "F1"}
    assert len(site.doors) == 2
    assert "corridor" in {a.id for a in site.areas}
    assert len(site.pois) == 8 and len(site.tours) == 3
    assert len(site.charging_stations) == 2 and len(site.wait_points) == 1
    assert len(site.buttons) == 2 and len(site.robots) == 3
    assert all(m.sampling_period_ms == 200 for m in site.modules)


def test_export_then_import_gives_the_same_site() -> None:
    site = demo_site()
    assert load_site_text(dump_site(site)) == site


def test_broken_site_is_refused_with_every_error_and_its_line() -> None:
    text = DEMO.read_text()
    text = text.replace("{id: gb2, floor: F0, x: 30, y: 8}", "{id: gb2, floor: F0, x: 30, y: up}")
    text = text.replace(
        "sampling_period_ms: 200\n    points:\n      - {name: button_landing",
        "sampling_period_ms: -5\n    points:\n      - {name: button_landing",
    )
    with pytest.raises(SiteInvalid) as info:
        load_site_text(text)
    issues = info.value.issues
    assert {i.loc for i in issues} == {"nodes[11].y", "modules[1].sampling_period_ms"}
    lines = text.splitlines()
    for issue in issues:
        assert issue.line is not None
        assert issue.loc.split(".")[-1] in lines[issue.line - 1]


def test_references_are_checked_all_at_once() -> None:
    text = DEMO.read_text()
    text = text.replace("points: [tapestries, globes, telescope]", "points: [tapestries, nothing]")
    text = text.replace("{a: gc2, b: gc3}", "{a: gc2, b: nowhere}")
    text = text.replace(
        "call: {module: otb_ground, point: lift_call}",
        "call: {module: otb_ground, point: lift_here}",
    )
    with pytest.raises(SiteInvalid) as info:
        load_site_text(text)
    messages = {(i.loc, i.message) for i in info.value.issues}
    assert ("tours[1].points[1]", "unknown point of interest 'nothing'") in messages
    assert ("edges[16].b", "unknown node 'nowhere'") in messages
    assert any(
        loc == "elevators[0].stops[0].call" and "is a discrete_input; it must be a coil" in msg
        for loc, msg in messages
    )
    assert len(info.value.issues) == 3


@pytest.mark.parametrize(
    "text",
    ["", "- just\n- a list\n", "name: [unclosed\n", "name: x\nfloors: []\nnodes: []\n"],
)
def test_garbage_is_refused_not_crashed(text: str) -> None:
    with pytest.raises(SiteInvalid) as info:
        load_site_text(text)
    assert info.value.issues


def test_shape_and_reference_errors_are_reported_in_one_pass() -> None:
    text = DEMO.read_text()
    text = text.replace("{id: gb2, floor: F0, x: 30, y: 8}", "{id: gb2, floor: F0, x: 30, y: up}")
    text = text.replace("{a: gc2, b: gc3}", "{a: gc2, b: nowhere}")
    with pytest.raises(SiteInvalid) as info:
        load_site_text(text)
    found = {(i.loc, i.message) for i in info.value.issues}
    assert ("edges[16].b", "unknown node 'nowhere'") in found
    assert any(loc == "nodes[11].y" for loc, _ in found)
    # gb2 exists (only its y is broken): edges and points naming it are not reported
    assert not any("'gb2'" in msg for _, msg in found)
    assert len(found) == 2


def test_site_check_command_lists_problems_with_lines(tmp_path: Path) -> None:
    runner = CliRunner()
    ok = runner.invoke(main, ["site", "check", str(DEMO)])
    assert ok.exit_code == 0 and "8 points of interest" in ok.output
    broken = tmp_path / "broken.yaml"
    broken.write_text(DEMO.read_text().replace("{a: gc2, b: gc3}", "{a: gc2, b: nowhere}"))
    bad = runner.invoke(main, ["site", "check", str(broken)])
    assert bad.exit_code == 1
    assert f"{broken}:" in bad.output and "edges[16].b: unknown node 'nowhere'" in bad.output


def test_alias_bombs_and_deep_nesting_are_refused_with_their_line() -> None:
    bomb = "name: x\na: &a [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]\n" + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 10)}]\n"
        for i in range(12)
    )
    with pytest.raises(SiteInvalid) as refused:
        load_site_text(bomb)
    [issue] = refused.value.issues
    assert issue.message == "more than 100 aliases" and issue.line == 13  # the 101st
    deep = "name: x\nnodes: " + "[" * 40 + "]" * 40 + "\n"
    with pytest.raises(SiteInvalid) as refused:
        load_site_text(deep)
    [issue] = refused.value.issues
    assert issue.message == "nested deeper than 32 levels" and issue.line == 2


def test_an_edge_making_a_cabin_a_through_way_is_refused() -> None:
    text = DEMO.read_text().replace(
        "  - {a: hall, b: lift0}\n", "  - {a: hall, b: lift0}\n  - {a: charge_b, b: lift0}\n"
    )
    with pytest.raises(SiteInvalid) as info:
        load_site_text(text)
    [issue] = info.value.issues
    assert issue.loc == "edges[4]" and issue.line is not None
    assert "cabin node 'lift0' of elevator lift a through-way" in issue.message
    assert "join 'charge_b' to 'hall' instead" in issue.message
