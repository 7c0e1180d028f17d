"""One table of task kinds: the Task Manager, the API, the panels and the site validator read
it, so a button's task is checked at site load exactly as a request of that kind would be."""

from __future__ import annotations

from typing import get_args

import pytest

from backend.api.tasks import TaskCreate
from guidebot.paths import ROOT
from guidebot.payloads.tasks import TaskRequest
from guidebot.site import SiteInvalid, load_site_text
from guidebot.site.graph import SiteGraph
from guidebot.task_kinds import (
    KINDS,
    MANUAL_KINDS,
    BadParams,
    TaskKind,
    UnknownTarget,
    check_params,
)
from guidebot.task_kinds import VISITOR_KINDS as PANEL_KINDS

from .helpers import DEMO, demo_site

ENTRANCE_TASK = "task: {kind: tour, params: {tour: ground}, priority: 5}"


def test_every_kind_has_its_net_and_every_consumer_the_same_kinds() -> None:
    assert set(get_args(TaskKind)) == set(KINDS)
    for kind, spec in KINDS.items():
        assert (ROOT / "petri_nets" / "library" / f"{spec.net}.pnml").is_file(), kind
        assert spec.duration_s > 0
    assert PANEL_KINDS == {"tour", "go_to_poi"}
    assert MANUAL_KINDS == {"go_to", "charge"}
    schema_kinds = TaskCreate.model_json_schema()["properties"]["kind"]["enum"]
    assert set(schema_kinds) == set(KINDS)
    assert set(TaskRequest.model_json_schema()["properties"]["kind"]["enum"]) == set(KINDS)


def test_targets_come_from_the_site() -> None:
    site = demo_site()
    graph = SiteGraph(site)
    assert KINDS["go_to_poi"].target(site, {"poi": site.pois[0].id}, graph) == site.pois[0].node
    station = site.charging_stations[0]
    assert KINDS["charge"].target(site, {}, graph) == station.node
    with pytest.raises(UnknownTarget, match="unknown charging station 'nowhere'") as info:
        KINDS["charge"].target(site, {"station": "nowhere"}, graph)
    assert info.value.param == "station"
    with pytest.raises(UnknownTarget, match="unknown node 'nowhere'"):
        KINDS["go_to"].target(site, {"node": "nowhere"}, graph)


def test_params_are_strict() -> None:
    assert check_params("tour", {"tour": "ground", "lang": None}) == {"tour": "ground"}
    with pytest.raises(BadParams, match=r"params.tuor: Extra inputs.*expected: tour, lang"):
        check_params("tour", {"tuor": "ground"})
    with pytest.raises(BadParams, match="unknown task kind 'dance'"):
        check_params("dance", {})


@pytest.mark.parametrize(
    ("task", "loc", "message"),
    [
        ("task: {kind: tour, params: {tour: nowhere}}", "params.tour", "unknown tour 'nowhere'"),
        ("task: {kind: tour, params: {tuor: ground}}", "params", "params.tuor: Extra inputs"),
        ("task: {kind: go_to, params: {node: nowhere}}", "params.node", "unknown node 'nowhere'"),
        (
            "task: {kind: charge, params: {station: nowhere}}",
            "params.station",
            "unknown charging station 'nowhere'",
        ),
        ("task: {kind: dance}", "kind", "Input should be 'tour', 'go_to_poi', 'charge' or"),
    ],
)
def test_a_button_task_is_checked_as_a_request_of_its_kind(
    task: str, loc: str, message: str
) -> None:
    text = DEMO.read_text()
    assert ENTRANCE_TASK in text
    with pytest.raises(SiteInvalid) as info:
        load_site_text(text.replace(ENTRANCE_TASK, task))
    found = [(i.loc, i.message) for i in info.value.issues]
    assert any(where == f"buttons[0].task.{loc}" and message in what for where, what in found), (
        found
    )
    assert len(found) == 1, found
