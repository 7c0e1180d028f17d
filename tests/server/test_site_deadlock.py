"""The static deadlock check (guidebot/site/deadlock.py, issue 36): a planted deadlock of two
restricted areas on a one-way ring is found with a way of reaching it; the demo museum is
proven free of one for 10 robots; a search too small for the site says it gave up."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from click.testing import CliRunner

from backend.site.cli import site as site_cli
from guidebot.site.deadlock import find_deadlock
from guidebot.site.validate import validate_site
from tests.server.helpers import DEMO, demo_site


def planted(one_way: bool = True) -> dict[str, Any]:
    """A one-way ring a1 -> a2 -> b1 -> b2 -> a1 of two back-to-back areas A and B, each with a
    point of interest inside (robots stop there), the hall x and the lobby y outside."""
    nodes = [
        {"id": n, "floor": "F0", "x": x, "y": y}
        for n, x, y in (("x", 0, 0), ("a1", 4, 0), ("a2", 8, 0), ("b1", 8, 4), ("b2", 4, 4))
    ] + [{"id": "y", "floor": "F0", "x": 0, "y": 4}]
    ring = [("a1", "a2"), ("a2", "b1"), ("b1", "b2"), ("b2", "a1")]
    return {
        "name": "Planted deadlock",
        "floors": [{"id": "F0"}],
        "nodes": nodes,
        "edges": [{"a": a, "b": b, "one_way": one_way} for a, b in ring]
        + [{"a": "x", "b": "a1"}, {"a": "y", "b": "b2"}],
        "pois": [
            {"id": "pa", "node": "a2", "text": "in A"},
            {"id": "pb", "node": "b1", "text": "in B"},
        ],
        "areas": [{"id": "A", "nodes": ["a1", "a2"]}, {"id": "B", "nodes": ["b1", "b2"]}],
        "robots": [
            {"name": "R1", "token": "robot-R1-planted-token", "start_node": "x"},
            {"name": "R2", "token": "robot-R2-planted-token", "start_node": "y"},
        ],
    }


def test_a_planted_deadlock_of_two_areas_on_a_one_way_ring_is_found() -> None:
    result = find_deadlock(validate_site(planted()), 2)
    assert result.deadlock, result.describe()
    assert sorted(result.cycle) == [("area A", "area B"), ("area B", "area A")]
    assert "a robot stopped in area A waits for area B" in result.describe()
    # The way there: each robot drives in and stops, then asks for the other's area.
    assert sum("(stops)" in step for step in result.trace) == 2
    assert sum("waits for" in step for step in result.trace) >= 1
    # One robot alone cannot deadlock; every state of it is explored.
    alone = find_deadlock(validate_site(planted()), 1)
    assert not alone.deadlock and alone.complete and alone.states > 1


def test_without_a_stop_inside_the_areas_nobody_waits_holding_one() -> None:
    doc = planted()
    doc["pois"] = []
    result = find_deadlock(validate_site(doc), 4)
    assert not result.deadlock and result.complete and "no robot ever waits" in result.reason
    # The full search says the same.
    full = find_deadlock(validate_site(doc), 4, shortcut=False)
    assert not full.deadlock and full.complete and full.states > 1


def test_the_demo_museum_is_proven_deadlock_free_for_ten_robots() -> None:
    result = find_deadlock(demo_site(), 10, shortcut=False)
    assert result.complete and not result.deadlock, result.describe()
    print(f"demo museum, 10 robots: {result.states} states in {result.seconds:.3f} s")


def test_a_search_bounded_below_the_site_gives_up_and_says_so() -> None:
    result = find_deadlock(validate_site(planted(one_way=False)), 2, max_states=3)
    assert not result.complete and not result.deadlock
    assert "gave up after 3 states" in result.describe() and "not proven" in result.describe()


def test_site_check_reports_the_cycle_with_the_areas_lines(tmp_path: Path) -> None:
    import yaml

    path = tmp_path / "planted.yaml"
    path.write_text(yaml.safe_dump(planted(), sort_keys=False))
    result = CliRunner().invoke(site_cli, ["check", str(path), "--deadlock-robots", "2"])
    assert result.exit_code == 1, result.output
    assert "can deadlock" in result.output and "area A" in result.output
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1) if "id: A" in text)
    assert f"{path}:{line}: areas[0]" in result.output
    ok = CliRunner().invoke(site_cli, ["check", str(DEMO), "--deadlock-robots", "10"])
    assert ok.exit_code == 0 and "no deadlock of 10 robots" in ok.output, ok.output
