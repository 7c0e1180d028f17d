"""Step-free tours (issue 41): edges with steps in the site (``Edge.steps``), the step-free
path search the Traffic Manager answers a step-free tour's legs with, and ``guidebot site
check``'s warning for the stops a step-free tour skips."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml
from click.testing import CliRunner

from backend.closures.routing import StepsOnly, step_free_path_of
from backend.site.cli import site as site_cli
from backend.testing import RunningServer
from guidebot.site.access import step_free_skips, step_free_warnings
from guidebot.site.graph import SiteGraph
from guidebot.site.validate import SiteInvalid, validate_site
from guidebot.site.yamlio import load_site_file
from tests.server.conftest import OPERATOR_TOKEN

ROOT = Path(__file__).resolve().parents[2]

# a -- b -- c, with a ramp too steep for a wheelchair from b to c, and a longer level way
# round through d; e is reached only over steps.
DOC: dict[str, Any] = {
    "name": "Steps",
    "floors": [{"id": "F0"}],
    "nodes": [
        {"id": "a", "floor": "F0", "x": 0, "y": 0},
        {"id": "b", "floor": "F0", "x": 5, "y": 0},
        {"id": "c", "floor": "F0", "x": 10, "y": 0},
        {"id": "d", "floor": "F0", "x": 7, "y": 6},
        {"id": "e", "floor": "F0", "x": 10, "y": 5},
    ],
    "edges": [
        {"a": "a", "b": "b"},
        {"a": "b", "b": "c", "steps": True},
        {"a": "b", "b": "d"},
        {"a": "d", "b": "c"},
        {"a": "c", "b": "e", "steps": True},
    ],
    "pois": [
        {"id": "pa", "name": "A", "node": "a", "text": "A."},
        {"id": "pc", "name": "C", "node": "c", "text": "C."},
        {"id": "pe", "name": "E", "node": "e", "text": "E."},
    ],
    "tours": [{"id": "all", "name": "All", "points": ["pa", "pe", "pc"]}],
}


def test_a_step_free_path_goes_round_the_steps_and_none_leads_over_steps_only() -> None:
    site = validate_site(DOC)
    graph = SiteGraph(site)
    plain = graph.shortest_path("a", "c")
    assert plain.nodes == ["a", "b", "c"] and graph.uses_steps(plain)
    # Robots take the steps; a step-free tour goes round them.
    assert step_free_path_of(graph, plain, {}).nodes == ["a", "b", "d", "c"]
    with pytest.raises(StepsOnly) as cut:
        step_free_path_of(graph, graph.shortest_path("a", "e"), {})
    assert cut.value.reason == "steps"  # what the visitor is told (web/lib/skipped.js)
    # The stop after a skipped one is looked for from where the tour is.
    tour = site.tour("all")
    assert tour is not None
    assert step_free_skips(site, graph, tour) == ["pe"]


def test_steps_is_a_yes_or_no() -> None:
    bad = {**DOC, "edges": [{"a": "a", "b": "b", "steps": "a few"}]}
    with pytest.raises(SiteInvalid) as exc:
        validate_site(bad)
    assert any(i.loc.startswith("edges[0].steps") for i in exc.value.issues)


def test_site_check_warns_of_the_stops_a_step_free_tour_skips(tmp_path: Path) -> None:
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(DOC))
    result = CliRunner().invoke(site_cli, ["check", str(path), "--deadlock-robots", "0"])
    assert result.exit_code == 0, result.output
    assert "warning: tours[0].points: a step-free tour of 'all' skips 'pe'" in result.output


def test_the_demo_marks_the_steps_to_the_loom() -> None:
    site = load_site_file(ROOT / "sites" / "demo_museum.yaml")
    warnings = step_free_warnings(site)
    assert [(w.loc, w.message) for w in warnings] == [
        (
            "tours[0].points",
            "a step-free tour of 'ground' skips 'loom': only steps lead there",
        )
    ]


def test_the_stops_a_step_free_tour_skips_count_the_closures() -> None:
    site = validate_site(DOC)
    graph = SiteGraph(site)
    tour = site.tour("all")
    assert tour is not None
    # d closed: the level way round to c is shut, only the ramp is left: c is skipped too.
    assert step_free_skips(site, graph, tour, {"d"}) == ["pe", "pc"]
    # c itself closed: every tour skips c and e (only c leads to e), not the steps' doing.
    assert step_free_skips(site, graph, tour, {"c"}) == []


async def test_the_menu_s_step_free_skips_follow_the_building_modes(
    server: RunningServer, http: Callable[[str | None], httpx.AsyncClient]
) -> None:
    staff = http(OPERATOR_TOKEN)

    async def skips() -> list[str]:
        menu = (await staff.get("/api/visitor")).json()
        return next(t["step_free_skips"] for t in menu["tours"] if t["id"] == "ground")  # type: ignore[no-any-return]

    assert await skips() == ["loom"]
    # The loom's gallery closed: every tour skips it now, for the closure, not for the steps.
    r = await staff.post(
        "/api/closures", json={"kind": "nodes", "nodes": ["gb2"], "reason": "cleaning"}
    )
    assert r.status_code == 201, r.text
    assert await skips() == []
    assert (await staff.delete(f"/api/closures/{r.json()['id']}")).status_code == 200
    assert await skips() == ["loom"]
