"""The site editor's server side: shared draft with revisions, publish without a restart,
kept versions, diff, roll back, YAML import/export of the draft, uploads, robots following."""

from __future__ import annotations

import asyncio
import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
import yaml

from backend.testing import RunningServer, running_server
from guidebot.client import HubClient
from guidebot.messages import Message
from guidebot.site.yamlio import load_site_text
from robot_agent.agent import AgentConfig, RobotAgent
from tests.server.conftest import OPERATOR_TOKEN, server_settings

pytestmark = pytest.mark.timeout(60)

DEMO_TEXT = (Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml").read_text()

Http = Callable[[str | None], httpx.AsyncClient]


async def _draft(admin: httpx.AsyncClient) -> dict[str, Any]:
    r = await admin.get("/api/site/draft")
    assert r.status_code == 200, r.text
    return r.json()  # type: ignore[no-any-return]


def _move_welcome(doc: dict[str, Any]) -> None:
    """The fair scenario: the welcome stand moves next to the sword, first in the ground tour."""
    doc["nodes"].append({"id": "stand_new", "floor": "F0", "x": 27.5, "y": 3})
    doc["edges"] += [{"a": "corridor_e", "b": "stand_new"}, {"a": "stand_new", "b": "gb1"}]
    next(p for p in doc["pois"] if p["id"] == "welcome")["node"] = "stand_new"
    ground = next(t for t in doc["tours"] if t["id"] == "ground")
    ground["points"] = ["mosaics", "welcome", "sword"]


async def test_edit_publish_history_diff_and_rollback(server: RunningServer, http: Http) -> None:
    admin = http(server.admin_token)
    state = await _draft(admin)
    assert state["issues"] == [] and state["base_version"] == state["live_version"]
    first = state["live_version"]
    doc = state["draft"]
    _move_welcome(doc)
    saved = await admin.put("/api/site/draft", json={"draft": doc, "revision": state["revision"]})
    assert saved.status_code == 200 and saved.json()["issues"] == []
    rev = saved.json()["revision"]
    # Not live before publish: the Traffic Manager still has no such node.
    path = await admin.get("/api/paths", params={"from_node": "entrance", "to_node": "stand_new"})
    assert path.status_code == 404
    published = await admin.post("/api/site/publish", json={"revision": rev, "note": "fair"})
    assert published.status_code == 200, published.text
    version = published.json()["version"]
    assert version == first + 1
    path = await admin.get("/api/paths", params={"from_node": "entrance", "to_node": "stand_new"})
    assert path.status_code == 200 and path.json()["nodes"][-1] == "stand_new"
    tour = (await admin.get("/api/tours")).json()
    ground = next(t for t in tour if t["id"] == "ground")
    assert [p["id"] if isinstance(p, dict) else p for p in ground["points"]][:2] == [
        "mosaics",
        "welcome",
    ]
    versions = (await admin.get("/api/site/versions")).json()
    assert [v["version"] for v in versions][:2] == [version, first]
    assert versions[0]["published_by"] == "admin" and versions[0]["note"] == "fair"
    diff = (await admin.get("/api/site/diff", params={"from": first, "to": version})).json()
    texts = [d["text"] for d in diff]
    assert "nodes stand_new: added" in texts
    assert any(t.startswith('pois welcome: node "hall" -> "stand_new"') for t in texts)
    assert any(t.startswith("tours ground: points") for t in texts)
    # Roll back: the old tour order is live again, as a new version.
    back = await admin.post("/api/site/rollback", json={"version": first})
    assert back.status_code == 200 and back.json()["version"] == version + 1
    tour = (await admin.get("/api/tours")).json()
    ground = next(t for t in tour if t["id"] == "ground")
    points = [p["id"] if isinstance(p, dict) else p for p in ground["points"]]
    assert points == ["welcome", "mosaics", "amphorae", "sword", "loom"]
    assert (await _draft(admin))["draft"]["tours"] == (await admin.get("/api/site")).json()["site"][
        "tours"
    ]


async def test_invalid_draft_is_saved_but_not_published(server: RunningServer, http: Http) -> None:
    admin = http(server.admin_token)
    state = await _draft(admin)
    doc = state["draft"]
    doc["pois"] = [p for p in doc["pois"] if p["id"] != "mosaics"]
    saved = await admin.put("/api/site/draft", json={"draft": doc, "revision": state["revision"]})
    issues = saved.json()["issues"]
    assert any("mosaics" in i["msg"] and i["loc"].startswith("tours[") for i in issues), issues
    refused = await admin.post("/api/site/publish", json={"revision": saved.json()["revision"]})
    assert refused.status_code == 422
    assert any("mosaics" in i["msg"] for i in refused.json()["detail"])
    assert (await admin.get("/api/site")).json()["version"] == state["live_version"]


async def test_two_editors_the_stale_one_is_refused(server: RunningServer, http: Http) -> None:
    alice, bob = http(server.admin_token), http(server.admin_token)
    a, b = await _draft(alice), await _draft(bob)
    a["draft"]["name"] = "Fair 2026"
    ok = await alice.put("/api/site/draft", json={"draft": a["draft"], "revision": a["revision"]})
    assert ok.status_code == 200
    b["draft"]["name"] = "Bob's name"
    late = await bob.put("/api/site/draft", json={"draft": b["draft"], "revision": b["revision"]})
    assert late.status_code == 409
    detail = late.json()["detail"]
    assert "changed by admin" in detail["msg"] and detail["revision"] == ok.json()["revision"]
    stale_publish = await bob.post("/api/site/publish", json={"revision": b["revision"]})
    assert stale_publish.status_code == 409
    assert (await _draft(bob))["draft"]["name"] == "Fair 2026"  # nothing of Alice's lost
    # The operator role cannot edit.
    op = http(OPERATOR_TOKEN)
    assert (await op.get("/api/site/draft")).status_code == 403


async def test_yaml_import_errors_have_lines_and_export_is_stable(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    state = await _draft(admin)
    broken = (
        "name: Broken\nfloors:\n  - {id: F0}\nnodes:\n  - {id: a, floor: F0, x: 0, y: 0}\n"
        "  - {id: b, floor: F9, x: 1, y: zero}\nedges:\n  - {a: a, b: nowhere}\n"
    )
    r = await admin.post(
        "/api/site/draft/import",
        params={"revision": state["revision"]},
        content=broken,
        headers={"Content-Type": "application/yaml"},
    )
    assert r.status_code == 422
    lines = {(i["loc"], i["line"]) for i in r.json()["detail"]}
    assert ("nodes[1].y", 6) in lines and ("edges[0].b", 8) in lines, lines
    assert (await _draft(admin))["revision"] == state["revision"]  # the draft is untouched
    exported = (await admin.get("/api/site/draft/export")).text
    r = await admin.post(
        "/api/site/draft/import",
        params={"revision": state["revision"]},
        content=exported,
        headers={"Content-Type": "application/yaml"},
    )
    assert r.status_code == 200, r.text
    again = (await admin.get("/api/site/draft/export")).text
    assert again == exported
    assert load_site_text(again).model_dump() == load_site_text(exported).model_dump()
    assert list(yaml.safe_load(again)) == list(yaml.safe_load(exported))


async def test_uploads_are_typed_and_limited(tmp_path: Path) -> None:
    site = tmp_path / "site.yaml"
    site.write_text(DEMO_TEXT)
    settings = server_settings(tmp_path).model_copy(update={"site": site})
    async with (
        running_server(settings) as server,
        httpx.AsyncClient(
            base_url=server.url, headers={"Authorization": f"Bearer {server.admin_token}"}
        ) as admin,
    ):
        png = b"\x89PNG\r\n\x1a\n" + b"\0" * 100
        r = await admin.post(
            "/api/site/uploads/plan", content=png, headers={"Content-Type": "image/png"}
        )
        assert r.status_code == 200 and r.json()["path"].startswith("uploads/")
        stored = tmp_path / r.json()["path"]
        assert await asyncio.to_thread(stored.read_bytes) == png
        got = await admin.get(f"/api/site/{r.json()['path']}")
        assert got.status_code == 200 and got.content == png
        assert got.headers["content-type"] == "image/png"
        wrong = await admin.post(
            "/api/site/uploads/plan", content=b"<html>", headers={"Content-Type": "text/html"}
        )
        assert wrong.status_code == 415
        big = await admin.post(
            "/api/site/uploads/plan",
            content=b"\0" * 4_000_001,
            headers={"Content-Type": "image/png"},
        )
        assert big.status_code == 413


async def test_publish_reaches_every_connected_robot(tmp_path: Path) -> None:
    settings = server_settings(tmp_path)
    async with running_server(settings) as server:
        site = load_site_text(DEMO_TEXT)
        agents = []
        try:
            for robot in site.robots[:2]:
                agent = RobotAgent(
                    AgentConfig(
                        name=robot.name,
                        server=server.url,
                        token=robot.token,
                        can=None,
                        start_node=robot.start_node,
                        speech_engine=None,
                    )
                )
                await agent.start()
                agents.append(agent)
            async with httpx.AsyncClient(
                base_url=server.url, headers={"Authorization": f"Bearer {server.admin_token}"}
            ) as admin:
                # Robots that connect say which version they run and catch up.
                async def caught_up(version: int) -> None:
                    while any(a.site_follower.version != version for a in agents):  # type: ignore[union-attr]  # noqa: ASYNC110
                        await asyncio.sleep(0.02)

                live = (await admin.get("/api/site")).json()["version"]
                await asyncio.wait_for(caught_up(live), 10)
                state = await _draft(admin)
                _move_welcome(state["draft"])
                rev = (
                    await admin.put(
                        "/api/site/draft",
                        json={"draft": state["draft"], "revision": state["revision"]},
                    )
                ).json()["revision"]
                version = (await admin.post("/api/site/publish", json={"revision": rev})).json()[
                    "version"
                ]
                await asyncio.wait_for(caught_up(version), 10)
                assert agents[0].navigator is not None and agents[0].navigator.planner is not None
                assert (
                    agents[0].navigator.planner("entrance", "stand_new")["nodes"][-1] == "stand_new"
                )

                async def rollout() -> dict[str, Any]:
                    while True:
                        status = (await admin.get("/api/site/rollout")).json()
                        if status["version"] == version and status["complete"]:
                            return status  # type: ignore[no-any-return]
                        await asyncio.sleep(0.05)

                status = await asyncio.wait_for(rollout(), 10)
                assert status["expected"] == ["R1", "R2"]
                assert status["ms"] is not None and status["ms"] < 5000
        finally:
            for agent in agents:
                await agent.stop()


async def test_a_draft_the_database_cannot_store_is_refused_and_nothing_changes(
    server: RunningServer, http: Http
) -> None:
    """An integer beyond 64 bits (found by the API fuzz): 422 with the reason, not a 500, and
    the stored draft and its revision stay as they were."""
    admin = http(server.admin_token)
    state = await _draft(admin)
    doc = copy.deepcopy(state["draft"])
    doc["nodes"][0]["x"] = 10**30
    r = await admin.put("/api/site/draft", json={"draft": doc, "revision": state["revision"]})
    assert r.status_code == 422, r.text
    assert "integers must fit in 64 bits" in r.json()["detail"]
    after = await _draft(admin)
    assert after["revision"] == state["revision"] and after["draft"] == state["draft"]
    saved = await admin.put(
        "/api/site/draft", json={"draft": after["draft"], "revision": after["revision"]}
    )
    assert saved.status_code == 200 and saved.json()["revision"] == state["revision"] + 1


async def test_a_robot_gets_the_published_site_whole_and_without_tokens(tmp_path: Path) -> None:
    """The rollout sends the site JSON written off the loop (a fragment): on the wire it is the
    site document itself, every node of it, the robots' tokens left out."""
    settings = server_settings(tmp_path)
    async with running_server(settings) as server:
        site = load_site_text(DEMO_TEXT)
        robot = HubClient(server.ws_url, site.robots[0].token)
        seen: list[Message] = []
        robot.subscribe("site_changed", seen.append)
        await robot.start()
        try:
            await robot.sync()
            headers = {"Authorization": f"Bearer {server.admin_token}"}
            async with httpx.AsyncClient(base_url=server.url, headers=headers) as admin:
                document = (await admin.get("/api/site")).json()["site"]
                _move_welcome(document)
                reply = await admin.put("/api/site", json=document)
                assert reply.status_code == 200, reply.text
                version = reply.json()["version"]

                async def arrived() -> Message:
                    while not any(m.payload["version"] == version for m in seen):  # noqa: ASYNC110
                        await asyncio.sleep(0.02)
                    return next(m for m in seen if m.payload["version"] == version)

                message = await asyncio.wait_for(arrived(), 10)
        finally:
            await robot.close()
    sent = message.payload["site"]
    assert isinstance(sent, dict)
    assert [n["id"] for n in sent["nodes"]] == [n["id"] for n in document["nodes"]]
    assert "stand_new" in {n["id"] for n in sent["nodes"]}
    assert all("token" not in r for r in sent["robots"])
    assert [r["name"] for r in sent["robots"]] == [r.name for r in site.robots]


async def test_a_server_without_a_site_file_keeps_uploads_in_its_site_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """No --site: uploads go to ./guidebot-site/uploads/ and are served as plans and media."""
    monkeypatch.chdir(tmp_path)
    settings = server_settings(tmp_path).model_copy(update={"site": None})
    async with (
        running_server(settings) as server,
        httpx.AsyncClient(
            base_url=server.url, headers={"Authorization": f"Bearer {server.admin_token}"}
        ) as admin,
    ):
        png = b"\x89PNG\r\n\x1a\n" + b"\1" * 64
        plan = await admin.post(
            "/api/site/uploads/plan", content=png, headers={"Content-Type": "image/png"}
        )
        assert plan.status_code == 200, plan.text
        svg = b'<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4"/>'
        media = await admin.post(
            "/api/site/uploads/media", content=svg, headers={"Content-Type": "image/svg+xml"}
        )
        assert media.status_code == 200, media.text
        stored = tmp_path / "guidebot-site" / plan.json()["path"]
        assert await asyncio.to_thread(stored.read_bytes) == png
        doc = yaml.safe_load(DEMO_TEXT)
        doc["floors"][0]["plan_image"] = plan.json()["path"]
        next(p for p in doc["pois"] if p["id"] == "welcome")["media"] = [media.json()["path"]]
        put = await admin.put("/api/site", json=doc)
        assert put.status_code == 200, put.text
        shown = await admin.get(f"/api/site/plans/{doc['floors'][0]['id']}")
        assert shown.status_code == 200 and shown.content == png
        picture = await admin.get(f"/media/{media.json()['path']}")
        assert picture.status_code == 200 and picture.content == svg
