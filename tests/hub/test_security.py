"""Authentication, roles, impersonation and bad input: refused clearly, nothing else breaks."""

from __future__ import annotations

import asyncio
import logging
import re
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import httpx
import orjson
import pytest
import websockets
from pydantic import ValidationError
from websockets.asyncio.client import ClientConnection
from websockets.exceptions import ConnectionClosed

from backend.auth import Role
from backend.hub.permissions import may_publish
from backend.settings import Settings
from backend.testing import RunningServer
from guidebot.client import HubClient, HubRefused
from guidebot.messages import Message
from guidebot.paths import ROOT
from robot_agent.link import UP_TYPES

from .conftest import TOKENS, ClientFactory

WAIT = 10.0


@asynccontextmanager
async def raw_socket(url: str, token: str | None = None) -> AsyncIterator[ClientConnection]:
    headers = {"Authorization": f"Bearer {token}"} if token else None
    async with websockets.connect(
        url, additional_headers=headers, proxy=None, compression=None
    ) as ws:
        yield ws


async def receive(ws: ClientConnection) -> dict[str, Any]:
    frame = await asyncio.wait_for(ws.recv(), WAIT)
    data = orjson.loads(frame)
    assert isinstance(data, dict), data
    return data


async def close_of(ws: ClientConnection) -> tuple[int, str]:
    with pytest.raises(ConnectionClosed) as closed:
        await asyncio.wait_for(ws.recv(), WAIT)
    assert closed.value.rcvd is not None
    return closed.value.rcvd.code, closed.value.rcvd.reason


async def authenticated(server: RunningServer, who: str) -> AsyncIterator[ClientConnection]:
    async with raw_socket(server.hub_url, TOKENS[who].token) as ws:
        welcome = await receive(ws)
        assert welcome["type"] == "welcome"
        yield ws


async def still_up(ws: ClientConnection) -> None:
    """The connection answers a ping after the refusal."""
    await ws.send(orjson.dumps({"type": "ping", "id": "alive"}).decode())
    while (message := await receive(ws))["type"] != "pong":
        pass
    assert message["correlation_id"] == "alive"


async def test_client_without_token_is_refused(server: RunningServer) -> None:
    async with raw_socket(server.hub_url) as ws:
        assert await close_of(ws) == (4001, "missing or unknown bearer token")


async def test_unknown_token_is_refused_and_client_does_not_retry(server: RunningServer) -> None:
    client = HubClient(server.hub_url, "not-a-known-token", backoff_initial=0.01)
    with pytest.raises(HubRefused) as refused:
        await client.start()
    assert refused.value.code == 4001


async def test_refused_sign_ins_are_logged_without_the_token(
    server: RunningServer, caplog: pytest.LogCaptureFixture
) -> None:
    """An operator sees who was turned away and why in the server's log, never the token."""
    caplog.set_level(logging.WARNING, logger="backend.hub.session")
    wrong = "wrong-token-do-not-log"
    async with raw_socket(server.hub_url, wrong) as ws:
        assert (await close_of(ws))[0] == 4001
    client = HubClient(server.hub_url, TOKENS["gui"].token, name="R1")
    with pytest.raises(HubRefused):
        await client.start()
    lines = [r.getMessage() for r in caplog.records if r.name == "backend.hub.session"]
    assert len(lines) == 2, lines
    assert lines[0] == "hub: sign-in refused from 127.0.0.1: 4001 missing or unknown bearer token"
    assert lines[1].startswith("hub: sign-in refused from 127.0.0.1 (token of 'gui'): 4003 ")
    assert "may only connect as 'gui'" in lines[1]
    tokens = (wrong, TOKENS["gui"].token)
    assert not any(token in r.getMessage() for r in caplog.records for token in tokens)


async def test_token_in_query_string_is_accepted(server: RunningServer) -> None:
    async with raw_socket(f"{server.hub_url}?token={TOKENS['gui'].token}") as ws:
        welcome = await receive(ws)
    assert welcome["payload"] == {"name": "gui", "role": "gui"}


async def test_a_query_parameter_the_hub_does_not_take_is_ignored_as_docs_say(
    server: RunningServer,
) -> None:
    """/ws takes ``token`` and ``name``; others are ignored, not refused (docs/protocol.md,
    "Connecting"; the REST routes refuse them, backend/rest/query.py): a misspelt ``name``
    shows in the welcome."""
    token = server.admin_token
    async with raw_socket(f"{server.hub_url}?token={token}&nmae=rgm&lang=de") as ws:
        welcome = await receive(ws)
    assert welcome["payload"] == {"name": "admin", "role": "admin"}
    async with raw_socket(f"{server.hub_url}?token={token}&name=rgm&lang=de") as ws:
        welcome = await receive(ws)
    assert welcome["payload"] == {"name": "rgm", "role": "admin"}
    documented = " ".join((ROOT / "docs" / "protocol.md").read_text().split())
    assert "`/ws` takes two query parameters, `token` and `name`, on both listeners" in documented
    assert "any other is ignored" in documented


async def test_gui_token_cannot_connect_as_a_robot(server: RunningServer) -> None:
    client = HubClient(server.hub_url, TOKENS["gui"].token, name="R1")
    with pytest.raises(HubRefused) as refused:
        await client.start()
    assert refused.value.code == 4003
    assert "may only connect as 'gui'" in refused.value.reason


async def test_second_gui_tab_gets_its_own_name(connect: ClientFactory) -> None:
    """As docs/protocol.md says: the taken name with ``#n``, n counted over the whole hub."""
    first, second = await connect("gui"), await connect("gui")
    assert first.name == "gui"
    assert second.name == "gui#1"
    operator, other_operator, third = await connect("op"), await connect("op"), await connect("gui")
    assert (operator.name, other_operator.name, third.name) == ("ann", "ann#2", "gui#3")
    documented = (ROOT / "docs" / "protocol.md").read_text()
    assert "the second tab of `gui_rc` is `gui_rc#1`" in " ".join(documented.split())


def test_the_demo_panel_token_docs_robot_names_is_the_demos() -> None:
    from guidebot.demo import demo

    default = next(p.default for p in demo.params if p.name == "panel_token")
    robot_md = (ROOT / "docs" / "robot.md").read_text()
    named = set(re.findall(r"`([a-z][a-z-]*panel-token)`", robot_md))
    assert named == {default}, named


async def test_a_second_admin_page_gets_its_own_name_and_the_first_stays(
    server: RunningServer, connect: ClientFactory
) -> None:
    first = await connect(server.admin_token, backoff_initial=0.01)
    second = await connect(server.admin_token)
    assert first.name == "admin" and second.name.startswith("admin#")
    await first.sync()  # still open: not replaced by the second page
    await second.sync()


async def test_an_admin_asking_for_its_name_takes_it_back(
    server: RunningServer, connect: ClientFactory
) -> None:
    old = await connect(server.admin_token, name="rgm", backoff_initial=0.01)
    new = await connect(server.admin_token, name="rgm")
    assert new.name == "rgm"
    failure = await asyncio.wait_for(old.wait_stopped(), WAIT)
    assert failure is not None and failure.code == 4000


async def test_reconnecting_robot_replaces_its_stale_connection(connect: ClientFactory) -> None:
    old = await connect("R1", backoff_initial=0.01)
    new = await connect("R1")
    assert new.name == "R1"
    failure = await asyncio.wait_for(old.wait_stopped(), WAIT)
    assert failure is not None and failure.code == 4000
    await new.sync()


async def test_robot_may_not_publish_as_another_robot(
    server: RunningServer, connect: ClientFactory
) -> None:
    gui = await connect("gui")
    seen: list[Message] = []
    gui.subscribe("*", seen.append)
    await gui.sync()
    async for ws in authenticated(server, "R1"):
        forged = {"type": "say", "id": "f1", "source": "R2", "payload": {"text": "hi"}}
        await ws.send(orjson.dumps(forged).decode())
        error = await receive(ws)
        assert error["type"] == "error"
        assert error["payload"]["code"] == "impersonation"
        assert error["correlation_id"] == "f1"
        state = {"type": "robot_state", "id": "f2", "payload": {"robot": "R2", "x": 1.0}}
        await ws.send(orjson.dumps(state).decode())
        error = await receive(ws)
        assert (error["payload"]["code"], error["payload"]["message_id"]) == ("impersonation", "f2")
        await still_up(ws)
        # its own state goes through, stamped with its name
        await ws.send(orjson.dumps({"type": "robot_state", "payload": {"robot": "R1"}}).decode())
        await still_up(ws)
    await gui.sync()
    assert [(m.type, m.source) for m in seen] == [("robot_state", "R1")]


@pytest.mark.parametrize(
    ("frame", "code"),
    [
        ("{not json", "malformed_json"),
        ("42", "malformed_message"),
        ('{"type": "teleport", "id": "u1", "payload": {}}', "unknown_type"),
        ('{"type": "say", "id": "p1", "payload": {"txt": "typo"}}', "invalid_payload"),
        ('{"type": "say", "id": "e1", "payload": {"text": "x"}, "colour": 1}', "invalid_envelope"),
        ('{"type": "subscribe", "payload": {"patterns": []}}', "invalid_payload"),
        ('{"id": "n1"}', "invalid_envelope"),
    ],
)
async def test_bad_input_gets_an_error_and_the_connection_stays_up(
    server: RunningServer, frame: str, code: str
) -> None:
    async for ws in authenticated(server, "R1"):
        await ws.send(frame)
        error = await receive(ws)
        assert error["type"] == "error"
        assert error["payload"]["code"] == code
        assert error["payload"]["reason"]
        await still_up(ws)


async def test_rest_roles(server: RunningServer, connect: ClientFactory) -> None:
    await connect("R1")
    async with httpx.AsyncClient(base_url=server.url) as http:
        assert (await http.get("/api/hub/clients")).status_code == 401
        bad = await http.get("/api/hub/clients", headers={"Authorization": "Bearer nope-nope"})
        assert bad.status_code == 401
        robot = {"Authorization": f"Bearer {TOKENS['R1'].token}"}
        assert (await http.get("/api/hub/clients", headers=robot)).status_code == 403
        operator = {"Authorization": f"Bearer {TOKENS['op'].token}"}
        listing = await http.get("/api/hub/clients", headers=operator)
        assert listing.status_code == 200
        assert [c["name"] for c in listing.json()["clients"]] == ["R1"]
        admin = await http.get("/api/hub/clients", params={"token": server.admin_token})
        assert admin.status_code == 200


def test_production_refuses_the_default_admin_token() -> None:
    with pytest.raises(ValidationError, match="GUIDEBOT_ADMIN_TOKEN"):
        Settings(environment="production")
    assert Settings(environment="production", admin_token="s3cret-admin-token").port == 8000


def test_settings_read_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("GUIDEBOT_PORT", "9123")
    monkeypatch.setenv(
        "GUIDEBOT_TOKENS", '[{"token": "tok-robot-R7", "name": "R7", "role": "robot"}]'
    )
    settings = Settings()
    assert settings.port == 9123
    assert settings.tokens[0].name == "R7" and settings.tokens[0].role == "robot"


async def test_tokens_in_query_strings_are_not_logged(
    server: RunningServer, listener: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    caplog.set_level(logging.INFO, logger="uvicorn.error")  # uvicorn sets its own level
    async with raw_socket(f"{server.hub_url}?token={TOKENS['gui'].token}") as ws:
        await receive(ws)
    server_side = [r for r in caplog.records if not r.name.startswith("websockets.client")]
    logged = "\n".join(r.getMessage() for r in server_side)
    if listener == "asgi":  # uvicorn logs the request line, redacted
        assert "token=***" in logged
    assert TOKENS["gui"].token not in logged


def test_a_robot_may_publish_every_type_its_link_sends_up() -> None:
    """The robot's link forwards UP_TYPES to the hub; one missing from the robot's publish
    permissions would be refused with forbidden_type (a door never released, a node never
    reported)."""
    refused = [t for t in UP_TYPES if not may_publish(Role.ROBOT, t)]
    assert refused == []
