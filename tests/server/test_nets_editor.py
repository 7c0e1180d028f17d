"""The RoboGraph editor's REST (/api/net-editor, docs/nets.md): library nets as the editor's
document, the engine's problems per element, PNML in and out, who may call it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import httpx
import pytest

from backend.testing import RunningServer
from petri_nets.builder import NetBuilder
from petri_nets.library import NetLibrary
from petri_nets.netjson import EditorNet, check_net, doc_to_editor, editor_to_pnml
from petri_nets.pnml import read_pnml, write_pnml
from petri_nets.validate import validate
from tests.server.conftest import OPERATOR_TOKEN, PANEL_TOKEN

pytestmark = pytest.mark.timeout(60)

Http = Callable[[str | None], httpx.AsyncClient]


def small_net() -> dict[str, Any]:
    """start -> go -> end (final): a net with nothing wrong."""
    return {
        "id": "small",
        "params": [{"name": "text", "required": False, "default": "hello"}],
        "places": [
            {
                "id": "start",
                "x": 40,
                "y": 40,
                "initial": 1,
                "action": {"kind": "publish", "type": "say", "body": '{"text": "${text}"}'},
            },
            {"id": "end", "x": 40, "y": 160, "final": True},
        ],
        "transitions": [
            {
                "id": "go",
                "x": 40,
                "y": 100,
                "condition": {"kind": "message", "type": "speech_ended"},
            }
        ],
        "arcs": [
            {"id": "a1", "source": "start", "target": "go"},
            {"id": "a2", "source": "go", "target": "end"},
        ],
    }


def test_every_library_net_goes_to_the_editor_and_back_unchanged_in_meaning() -> None:
    library = NetLibrary()
    for name in library.names():
        doc = library.get(name).doc
        net = EditorNet.model_validate(doc_to_editor(doc))
        assert check_net(net) == [], name
        back, problems = read_pnml(editor_to_pnml(net), f"{name}.pnml")
        assert back is not None and problems == [] and validate(back) == [], name
        assert [(p.id, p.initial, p.final, p.action) for p in back.places] == [
            (p.id, p.initial, p.final, p.action) for p in doc.places
        ], name
        assert [(a.source, a.target, a.weight) for a in back.arcs] == [
            (a.source, a.target, a.weight) for a in doc.arcs
        ]
        assert [t.priority for t in back.transitions] == [t.priority for t in doc.transitions]


async def test_check_names_the_element_of_each_problem(server: RunningServer, http: Http) -> None:
    admin = http(server.admin_token)
    r = await admin.post("/api/net-editor/check", json=small_net())
    assert r.status_code == 200, r.text
    assert r.json() == {"problems": []}
    bad = small_net()
    bad["places"][0]["action"] = {"kind": "publish", "body": '{"text": "${missing}"}'}
    bad["transitions"].append({"id": "loose", "x": 0, "y": 0})
    bad["arcs"].append({"id": "a3", "source": "start", "target": "end"})
    r = await admin.post("/api/net-editor/check", json=bad)
    problems = r.json()["problems"]
    by_element = {(p["element"], p["message"]) for p in problems}
    assert ("place:start", "place start: a publish action needs a type") in by_element
    assert (
        "place:start",
        "place start: parameter 'missing' is used but not declared",
    ) in by_element
    assert (
        "transition:loose",
        "transition loose has no input place: it would fire forever",
    ) in by_element
    assert ("arc:a3", "arc a3: an arc must join a place and a transition") in by_element


async def test_a_net_document_that_is_not_one_is_refused_with_its_place(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    bad = small_net()
    bad["places"][0]["initial"] = -1
    r = await admin.post("/api/net-editor/check", json=bad)
    assert r.status_code == 422
    assert ["body", "places", 0, "initial"] in [e["loc"] for e in r.json()["detail"]]


async def test_pnml_in_and_out(server: RunningServer, http: Http) -> None:
    admin = http(server.admin_token)
    r = await admin.post("/api/net-editor/export", json=small_net())
    assert r.status_code == 200
    assert r.headers["content-type"].startswith("application/xml")
    assert 'filename="small.pnml"' in r.headers["content-disposition"]
    pnml = r.content
    r = await admin.post(
        "/api/net-editor/import", content=pnml, headers={"Content-Type": "application/xml"}
    )
    assert r.status_code == 200, r.text
    net = r.json()["net"]
    assert net["layout"] == "pnml"
    assert [(p["id"], p["x"], p["y"]) for p in net["places"]] == [
        ("start", 40, 40),
        ("end", 40, 160),
    ]
    assert net["params"] == [{"name": "text", "required": False, "default": "hello"}]


@pytest.mark.parametrize(
    ("body", "says"),
    [
        (b"<pnml><net id='x'><place id='p'></net></pnml>", "upload.pnml:1:"),
        (b"<html/>", "root element is <html>, expected <pnml>"),
        (b"   ", "the PNML file is empty"),
    ],
)
async def test_a_malformed_pnml_file_is_refused_with_what_is_wrong(
    server: RunningServer, http: Http, body: bytes, says: str
) -> None:
    r = await http(server.admin_token).post(
        "/api/net-editor/import", content=body, headers={"Content-Type": "application/xml"}
    )
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert isinstance(detail, list) and any(says in line for line in detail), detail


async def test_a_pnml_file_too_large_is_refused(server: RunningServer, http: Http) -> None:
    r = await http(server.admin_token).post(
        "/api/net-editor/import",
        content=b" " * 2_000_001,
        headers={"Content-Type": "application/xml"},
    )
    assert r.status_code == 413


async def test_library_nets_and_vocabulary_for_staff_only(
    server: RunningServer, http: Http
) -> None:
    operator = http(OPERATOR_TOKEN)
    r = await operator.get("/api/net-editor/library/explain_point")
    assert r.status_code == 200
    assert r.json()["id"] == "explain_point" and r.json()["places"]
    assert (await operator.get("/api/net-editor/library/nope")).status_code == 404
    vocabulary = (await operator.get("/api/net-editor/vocabulary")).json()
    assert vocabulary["action_kinds"] == ["publish", "timer", "run", "kill", "next"]
    assert "text" in vocabulary["message_types"]["say"]
    assert (await operator.post("/api/net-editor/check", json=small_net())).status_code == 200
    panel = http(PANEL_TOKEN)
    for method, path in [
        ("GET", "/api/net-editor/vocabulary"),
        ("GET", "/api/net-editor/library/explain_point"),
        ("POST", "/api/net-editor/check"),
        ("POST", "/api/net-editor/export"),
        ("POST", "/api/net-editor/import"),
    ]:
        body = small_net() if method == "POST" else None
        assert (await panel.request(method, path, json=body)).status_code == 403, path
        assert (await http(None).request(method, path, json=body)).status_code == 401, path


async def test_simulate_runs_the_net_against_the_scripted_environment(
    server: RunningServer, http: Http
) -> None:
    operator = http(OPERATOR_TOKEN)
    r = await operator.post("/api/net-editor/simulate", json={"net": small_net()})
    assert r.status_code == 200, r.text
    result = r.json()
    assert result["outcome"] == "done" and result["fired"] == ["go"]
    assert result["final_marking"] == {"end": 1}
    said = [m for m in result["trace"] if m["type"] == "say"]
    assert [m["payload"] for m in said] == [{"text": "hello"}]
    # Never answered: the net waits for ever (stuck).
    r = await operator.post(
        "/api/net-editor/simulate",
        json={"net": small_net(), "params": {"text": "bye"}, "replies": {"say": []}},
    )
    assert r.json()["outcome"] == "stuck" and r.json()["final_marking"] == {"start": 1}


async def test_a_net_that_cannot_run_is_refused_with_the_reason(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    net = small_net()
    net["params"] = [{"name": "text", "required": True}]
    r = await admin.post("/api/net-editor/simulate", json={"net": net})
    assert r.status_code == 422
    assert "text" in r.json()["detail"]
    net = small_net()
    net["transitions"].append({"id": "loose"})
    r = await admin.post("/api/net-editor/simulate", json={"net": net})
    assert r.status_code == 422
    assert "transition loose has no input place" in r.json()["detail"]
    r = await admin.post(
        "/api/net-editor/simulate", json={"net": small_net(), "replies": {"say": [{"x": 1}]}}
    )
    assert r.status_code == 422 and "needs a" in r.json()["detail"]


async def test_analyse_explores_the_reachability_graph(server: RunningServer, http: Http) -> None:
    operator = http(OPERATOR_TOKEN)
    r = await operator.post("/api/net-editor/analyse", json={"net": small_net()})
    assert r.status_code == 200, r.text
    assert r.json() == {
        "states": 2,
        "complete": True,
        "bounded": True,
        "bound": 1,
        "unbounded_places": [],
        "dead_transitions": [],
        "dead_ends": 0,
    }
    pump = small_net()
    pump["arcs"].append({"id": "a3", "source": "go", "target": "start"})
    r = await operator.post("/api/net-editor/analyse", json={"net": pump, "max_states": 10})
    assert r.json()["bounded"] is False and r.json()["unbounded_places"] == ["end"]
    r = await operator.post("/api/net-editor/analyse", json={"net": pump, "max_states": 0})
    assert r.status_code == 422


def chain(places: int) -> bytes:
    """A net of ``places`` places in a row: larger than the API's default body limit."""
    builder = NetBuilder("chain").place("p0", initial=1)
    for i in range(1, places):
        builder.place(f"p{i}", final=i == places - 1)
        builder.transition(f"t{i}", [f"p{i - 1}"], [f"p{i}"])
    return write_pnml(builder.build())


async def test_a_200_place_net_opens_checks_and_exports(server: RunningServer, http: Http) -> None:
    admin = http(server.admin_token)
    pnml = chain(200)
    assert len(pnml) > 64 * 1024  # above the default body limit of the API
    r = await admin.post(
        "/api/net-editor/import", content=pnml, headers={"Content-Type": "application/xml"}
    )
    assert r.status_code == 200, r.text
    net = r.json()["net"]
    assert len(net["places"]) == 200
    r = await admin.post("/api/net-editor/check", json=net)
    assert r.status_code == 200 and r.json() == {"problems": []}
    r = await admin.post("/api/net-editor/export", json=net)
    assert r.status_code == 200 and len(r.content) > 64 * 1024


async def test_bend_points_go_out_and_come_back(server: RunningServer, http: Http) -> None:
    admin = http(server.admin_token)
    net = small_net()
    net["arcs"][0]["points"] = [[80, 60], [80, 90]]
    pnml = (await admin.post("/api/net-editor/export", json=net)).content
    r = await admin.post(
        "/api/net-editor/import", content=pnml, headers={"Content-Type": "application/xml"}
    )
    arcs = r.json()["net"]["arcs"]
    assert [a["points"] for a in arcs] == [[[80, 60], [80, 90]], []]


async def test_simulate_with_the_replies_chosen_one_at_a_time(
    server: RunningServer, http: Http
) -> None:
    """Nothing answers but the replies chosen: the answer says what the net waits for."""
    admin = http(server.admin_token)
    first = await admin.post("/api/net-editor/simulate", json={"net": small_net(), "chosen": []})
    assert first.status_code == 200, first.text
    result = first.json()
    assert result["outcome"] == "waiting" and result["next_timer"] is None
    assert result["waiting_for"] == [
        {
            "instance_id": "small#run",
            "net": "small",
            "transition": "go",
            "type": "speech_ended",
            "payload": {},
        }
    ]
    assert [m["type"] for m in result["trace"] if m["source"] == "dispatch"].count("say") == 1
    chosen = [{"type": "speech_ended", "payload": {"text": "hello"}}]
    done = await admin.post("/api/net-editor/simulate", json={"net": small_net(), "chosen": chosen})
    assert done.json()["outcome"] == "done" and done.json()["waiting_for"] == []
    bad = await admin.post(
        "/api/net-editor/simulate", json={"net": small_net(), "chosen": [{"payload": {}}]}
    )
    assert bad.status_code == 422 and "type" in bad.json()["detail"]
