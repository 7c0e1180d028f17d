"""The net library the RoboGraph editor publishes into (docs/nets.md, "Publish"): versions
kept with who and when, a readable diff, restore, the engine's rules (and the nets that use a
net) deciding what is accepted, who may publish, published nets kept across a restart, and a
robot agent that follows."""

from __future__ import annotations

import asyncio
import copy
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest

from backend.testing import RunningServer, running_server
from guidebot.site.yamlio import load_site_text
from guidebot.testing import wait_until
from robot_agent.agent import AgentConfig, RobotAgent
from tests.server.conftest import OPERATOR_TOKEN, server_settings

pytestmark = pytest.mark.timeout(60)

Http = Callable[[str | None], httpx.AsyncClient]
DEMO_TEXT = (Path(__file__).resolve().parents[2] / "sites" / "demo_museum.yaml").read_text()
NEW_WORDS = '{"text": "New words: ${text}", "lang": "${lang}"}'


async def explain_point(admin: httpx.AsyncClient) -> dict[str, Any]:
    reply = await admin.get("/api/net-editor/library/explain_point")
    assert reply.status_code == 200, reply.text
    return dict(reply.json())


def with_new_words(net: dict[str, Any]) -> dict[str, Any]:
    """explain_point saying other words: its speech place's body changed."""
    net = copy.deepcopy(net)
    place = next(p for p in net["places"] if p["id"] == "synthesize_text")
    place["action"]["body"] = NEW_WORDS
    return net


def speech_body(net: dict[str, Any]) -> str:
    return str(next(p for p in net["places"] if p["id"] == "synthesize_text")["action"]["body"])


async def test_publish_keeps_every_version_compares_them_and_restores_one(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    shipped = await explain_point(admin)
    before = (await admin.get("/api/net-editor/versions/explain_point")).json()
    assert before["live"] == 0 and before["versions"] == [] and before["shipped"] is True

    reply = await admin.post(
        "/api/net-editor/publish", json={"net": with_new_words(shipped), "note": "new words"}
    )
    assert reply.status_code == 200, reply.text
    assert reply.json()["version"] == 1 and reply.json()["published_by"] == "admin"
    assert speech_body(await explain_point(admin)) == NEW_WORDS
    # The editor's simulation runs the published version of a sub-net too.
    go_to_poi = (await admin.get("/api/net-editor/library/go_to_poi")).json()
    run = await admin.post(
        "/api/net-editor/simulate",
        json={"net": go_to_poi, "params": {"node": "n1", "text": "Look"}},
    )
    said = [m["payload"]["text"] for m in run.json()["trace"] if m["type"] == "say"]
    assert said == ["New words: Look"]

    history = (await admin.get("/api/net-editor/versions/explain_point")).json()
    assert history["live"] == 1
    assert [(v["version"], v["published_by"], v["note"]) for v in history["versions"]] == [
        (1, "admin", "new words")
    ]
    diff = (await admin.get("/api/net-editor/diff/explain_point?old=0&new=1")).json()
    assert diff["changes"] == [
        "~ place synthesize_text: action.body "
        '"{\\"text\\": \\"${text}\\", \\"lang\\": \\"${lang}\\"}" → '
        '"{\\"text\\": \\"New words: ${text}\\", \\"lang\\": \\"${lang}\\"}"'
    ]
    old = (await admin.get("/api/net-editor/versions/explain_point/0")).json()
    assert speech_body(old) == speech_body(shipped)

    restored = await admin.post("/api/net-editor/restore/explain_point/0", json={})
    assert restored.status_code == 200, restored.text
    assert restored.json()["version"] == 2 and restored.json()["note"] == "restored version 0"
    assert speech_body(await explain_point(admin)) == speech_body(shipped)
    diff = (await admin.get("/api/net-editor/diff/explain_point?old=0&new=2")).json()
    assert diff["changes"] == []
    missing = await admin.get("/api/net-editor/versions/explain_point/9")
    assert missing.status_code == 404
    huge = await admin.get(f"/api/net-editor/versions/explain_point/{2**63}")  # the fuzz's
    assert huge.status_code == 422


async def test_a_net_the_engine_or_the_library_would_not_run_is_refused(
    server: RunningServer, http: Http
) -> None:
    admin = http(server.admin_token)
    shipped = await explain_point(admin)
    # A transition no place feeds: the engine's own check.
    broken = copy.deepcopy(shipped)
    broken["arcs"] = [a for a in broken["arcs"] if a["target"] != "text_spoken"]
    reply = await admin.post("/api/net-editor/publish", json={"net": broken})
    assert reply.status_code == 422
    assert any("transition:text_spoken" in p for p in reply.json()["detail"])
    # A new required parameter: give_tour and go_to_poi run explain_point without it.
    stricter = copy.deepcopy(shipped)
    stricter["params"].append({"name": "voice", "required": True, "default": None})
    reply = await admin.post("/api/net-editor/publish", json={"net": stricter})
    assert reply.status_code == 422
    said = " ".join(reply.json()["detail"])
    assert "give_tour" in said and "voice" in said
    # A net running a sub-net the library does not have.
    orphan = copy.deepcopy(shipped)
    orphan["id"] = "explain_twice"
    orphan["places"][0]["action"]["net"] = "no_such_net"
    faced = next(t for t in orphan["transitions"] if t["id"] == "people_faced")
    faced["condition"]["net"] = "no_such_net"
    reply = await admin.post("/api/net-editor/publish", json={"net": orphan})
    assert reply.status_code == 422
    assert "'no_such_net' is not in the library" in " ".join(reply.json()["detail"])
    # Nothing was stored, nothing changed.
    history = (await admin.get("/api/net-editor/versions/explain_point")).json()
    assert history["versions"] == [] and history["library_version"] == 0
    assert (await admin.get("/api/net-editor/versions/explain_twice")).status_code == 404
    assert speech_body(await explain_point(admin)) == speech_body(shipped)


async def test_a_new_net_joins_the_library_and_only_who_may_edit_nets_publishes(
    server: RunningServer, http: Http
) -> None:
    admin, operator = http(server.admin_token), http(OPERATOR_TOKEN)
    net = copy.deepcopy(await explain_point(admin))
    net["id"] = "explain_again"
    assert (await operator.post("/api/net-editor/publish", json={"net": net})).status_code == 403
    assert (await operator.get("/api/net-editor/vocabulary")).json()["may_publish"] is False
    assert (await admin.get("/api/net-editor/vocabulary")).json()["may_publish"] is True
    reply = await admin.post("/api/net-editor/publish", json={"net": net})
    assert reply.status_code == 200, reply.text
    assert "explain_again" in (await operator.get("/api/nets")).json()
    history = (await operator.get("/api/net-editor/versions/explain_again")).json()
    assert history["live"] == 1 and history["shipped"] is False
    refused = await operator.post("/api/net-editor/restore/explain_again/1", json={})
    assert refused.status_code == 403
    # The debugger's commands name a running instance (docs/nets.md, "Attach").
    body = {"target": "R1", "instance_id": "nothing#1", "command": "step"}
    assert (await operator.post("/api/net-editor/debug", json=body)).status_code == 403
    missing = await admin.post("/api/net-editor/debug", json=body)
    assert missing.status_code == 404 and "nothing#1" in missing.json()["detail"]


async def test_published_nets_are_kept_across_a_restart(tmp_path: Path) -> None:
    settings = server_settings(tmp_path)
    headers = {"Authorization": f"Bearer {settings.admin_token}"}
    async with running_server(settings) as server:
        async with httpx.AsyncClient(base_url=server.url, headers=headers) as admin:
            net = with_new_words(await explain_point(admin))
            reply = await admin.post("/api/net-editor/publish", json={"net": net})
            assert reply.status_code == 200, reply.text
    async with running_server(settings) as server:
        async with httpx.AsyncClient(base_url=server.url, headers=headers) as admin:
            assert speech_body(await explain_point(admin)) == NEW_WORDS
            status = (await admin.get("/api/net-editor/rollout")).json()
            assert status["version"] == 1


async def test_a_robot_installs_what_is_published_and_catches_up_when_it_connects(
    tmp_path: Path,
) -> None:
    """One robot connected when the net is published, one that connects later: both start
    explain_point's new version (published nets reach the robot's own library)."""
    site = load_site_text(DEMO_TEXT)
    async with running_server(server_settings(tmp_path)) as server:
        headers = {"Authorization": f"Bearer {server.admin_token}"}
        agents: list[RobotAgent] = []

        async def robot(index: int) -> RobotAgent:
            spec = site.robots[index]
            agent = RobotAgent(
                AgentConfig(
                    name=spec.name,
                    server=server.url,
                    token=spec.token,
                    can=None,
                    start_node=spec.start_node,
                    speech_engine=None,
                )
            )
            await agent.start()
            agents.append(agent)
            return agent

        try:
            first = await robot(0)
            async with httpx.AsyncClient(base_url=server.url, headers=headers) as admin:
                net = with_new_words(await explain_point(admin))
                reply = await admin.post("/api/net-editor/publish", json={"net": net})
                assert reply.status_code == 200, reply.text
                seq = reply.json()["seq"]
                assert first.net_follower is not None
                await wait_until(lambda: first.net_follower.version == seq)  # type: ignore[union-attr]
                second = await robot(1)
                assert second.net_follower is not None
                await wait_until(lambda: second.net_follower.version == seq)  # type: ignore[union-attr]
                for agent in agents:
                    running = agent.dispatch.library.get("explain_point")
                    said = next(p for p in running.doc.places if p.id == "synthesize_text")
                    assert said.action is not None and "New words" in said.action.body

                async def everyone_says() -> dict[str, Any]:
                    while True:
                        status = (await admin.get("/api/net-editor/rollout")).json()
                        if status["robots"] == {"R1": seq, "R2": seq}:
                            return dict(status)
                        await asyncio.sleep(0.02)

                await asyncio.wait_for(everyone_says(), 10)
        finally:
            for agent in agents:
                await agent.stop()
