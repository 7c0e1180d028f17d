"""Step-free tours and visits (issue 41): edges with steps in the site (``Edge.steps``), the
step-free path search the Traffic Manager answers a step-free tour's legs with, ``guidebot site
check``'s warnings, a step-free tour whose first stop only steps lead to, and step-free visits
to one point (refused where only steps lead)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml
from click.testing import CliRunner

from backend.detours import StepsOnly, step_free_path_of
from backend.site.cli import site as site_cli
from backend.tasks.model import InvalidTask, Task
from backend.tasks.targets import net_params, target_node
from backend.testing import RunningServer, running_server
from guidebot.site.access import step_free_skips, step_free_warnings, steps_only_nodes
from guidebot.site.graph import SiteGraph
from guidebot.site.validate import SiteInvalid, validate_site
from guidebot.site.yamlio import load_site_file
from tests.server.conftest import OPERATOR_TOKEN, PANEL_TOKEN, server_settings

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
        ("pois[4]", "only steps lead to 'loom': a step-free visit is refused"),
        (
            "tours[0].points",
            "a step-free tour of 'ground' skips 'loom': only steps lead there",
        ),
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


# The first stop of "e_first" (e) and the point pe are reached only over steps from the rest.
FIRST = {
    **DOC,
    "tours": [
        {"id": "e_first", "name": "E first", "points": ["pe", "pa", "pc"]},
        {"id": "rest", "name": "The rest", "points": ["pa", "pc"]},
        {"id": "e_only", "name": "E only", "points": ["pe"]},
    ],
}


def _task(kind: str, params: dict[str, Any]) -> Task:
    return Task(id="t1", kind=kind, params=params, priority=5, requester="panel-1", seq=1)


def test_a_step_free_tour_whose_first_stop_only_steps_lead_to_starts_at_the_next() -> None:
    site = validate_site(FIRST)
    graph = SiteGraph(site)
    assert steps_only_nodes(graph) == {"e"}
    tour = site.tour("e_first")
    assert tour is not None
    assert step_free_skips(site, graph, tour) == ["pe"]  # the first stop too, now
    assert step_free_skips(site, graph, site.tour("rest")) == []  # type: ignore[arg-type]
    # The robot meets the visitor at the first stop a wheelchair reaches ...
    assert target_node(site, graph, "tour", {"tour": "e_first", "step_free": True}) == "a"
    assert target_node(site, graph, "tour", {"tour": "e_first"}) == "e"
    # ... is given the tour from there, and the visitor is told why the first was skipped.
    given = net_params(site, _task("tour", {"tour": "e_first", "step_free": True}))
    assert [(p["poi"], p["index"], p["total"]) for p in given["points"]] == [
        ("pa", 2, 3),
        ("pc", 3, 3),
    ]
    assert given["skipped"] == [{"index": 1, "poi": "pe", "name": "E", "reason": "steps"}]
    assert given["step_free"] is True
    plain = net_params(site, _task("tour", {"tour": "e_first"}))
    assert [p["poi"] for p in plain["points"]] == ["pe", "pa", "pc"] and "skipped" not in plain
    # A step-free tour with no stop a wheelchair reaches is refused, saying why.
    with pytest.raises(InvalidTask, match="only steps lead to every stop of tour 'e_only'"):
        target_node(site, graph, "tour", {"tour": "e_only", "step_free": True})


def test_a_step_free_visit_to_a_point_only_steps_lead_to_is_refused() -> None:
    site = validate_site(FIRST)
    graph = SiteGraph(site)
    with pytest.raises(InvalidTask, match="only steps lead to point 'pe': no step-free visit"):
        target_node(site, graph, "go_to_poi", {"poi": "pe", "step_free": True})
    assert target_node(site, graph, "go_to_poi", {"poi": "pe"}) == "e"  # it walks the steps
    assert target_node(site, graph, "go_to_poi", {"poi": "pc", "step_free": True}) == "c"
    given = net_params(site, _task("go_to_poi", {"poi": "pc", "step_free": True}))
    assert given["step_free"] is True and given["node"] == "c"
    # site check says so of the point as well as of the tours.
    assert ("pois[2]", "only steps lead to 'pe': a step-free visit is refused") in [
        (w.loc, w.message) for w in step_free_warnings(site)
    ]


async def test_step_free_point_visits_over_the_api(
    server: RunningServer, http: Callable[[str | None], httpx.AsyncClient]
) -> None:
    panel = http(PANEL_TOKEN)
    menu = (await panel.get("/api/visitor")).json()
    # Marked before anyone asks: the loom is down three steps, the rest is level.
    assert {p["id"]: p["steps_only"] for p in menu["pois"]} == {
        p["id"]: p["id"] == "loom" for p in menu["pois"]
    }
    r = await panel.post(
        "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "loom", "step_free": True}}
    )
    assert r.status_code == 422, r.text
    assert "only steps lead to point 'loom': no step-free visit" in r.text
    for bad in ("yes", 1, "true", None):
        r = await panel.post(
            "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "mosaics", "step_free": bad}}
        )
        if bad is None:  # left out: the usual visit
            assert r.status_code == 201, r.text
            assert "step_free" not in r.json()["params"]
            continue
        assert r.status_code == 422, r.text
        assert "params.step_free" in r.text
    r = await panel.post(
        "/api/tasks", json={"kind": "tour", "params": {"tour": "ground", "step_free": "yes"}}
    )
    assert r.status_code == 422 and "params.step_free" in r.text, r.text
    r = await panel.post(
        "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "mosaics", "step_free": True}}
    )
    assert r.status_code == 201, r.text
    assert r.json()["params"]["step_free"] is True
    assert (await panel.get("/api/visitor?step_free=maybe")).status_code == 422


async def test_a_step_free_tour_s_length_leaves_out_the_first_stop_it_skips(
    tmp_path: Path,
) -> None:
    path = tmp_path / "site.yaml"
    path.write_text(yaml.safe_dump(FIRST))
    settings = server_settings(tmp_path)
    settings.site = path
    async with (
        running_server(settings) as srv,
        httpx.AsyncClient(
            base_url=srv.url, headers={"Authorization": f"Bearer {PANEL_TOKEN}"}, timeout=10
        ) as panel,
    ):

        async def lengths(query: str) -> dict[str, float]:
            menu = (await panel.get(f"/api/visitor{query}")).json()
            return {t["id"]: t["estimate"]["duration_s"] for t in menu["tours"]}

        plain, step_free = await lengths(""), await lengths("?step_free=true")
        # What the menu says it skips and how long it says the tour takes agree: the step-free
        # "E first" is "The rest"; the tour as asked for without steps is longer.
        assert step_free["e_first"] == pytest.approx(plain["rest"])
        assert plain["e_first"] > plain["rest"]
        assert step_free["rest"] == pytest.approx(plain["rest"])
        menu = (await panel.get("/api/visitor?step_free=true")).json()
        assert menu["step_free"] is True
        assert [t["step_free_skips"] for t in menu["tours"]] == [["pe"], [], ["pe"]]
