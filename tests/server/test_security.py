"""Security over a real server: hashed tokens, production refusals, rate limits, body limits,
validation errors without echoes, consistent status codes, history across restarts."""

from __future__ import annotations

import asyncio
import logging
import sqlite3
from pathlib import Path
from typing import Any

import httpx
import orjson
import pytest
import websockets
from pydantic import ValidationError
from websockets.exceptions import ConnectionClosed

from backend.app import create_app
from backend.auth import token_digest
from backend.settings import Settings, StaticToken, describe_errors
from backend.site.tokens import InsecureSite
from backend.testing import running_server

from .conftest import OPERATOR_TOKEN, PANEL_TOKEN, server_settings

GROUND: dict[str, Any] = {"kind": "tour", "params": {"tour": "ground"}}
R1_TOKEN = "robot-R1-demo-token"
WAIT = 10.0


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


async def test_robot_tokens_are_stored_and_served_only_as_digests(tmp_path: Path) -> None:
    settings = server_settings(tmp_path)
    async with running_server(settings) as srv, httpx.AsyncClient(base_url=srv.url) as http:
        site = (await http.get("/api/site", headers=bearer(srv.admin_token))).json()["site"]
        tokens = {r["name"]: r["token"] for r in site["robots"]}
        assert tokens["R1"] == token_digest(R1_TOKEN)
        assert (await http.get("/api/robots/R1", headers=bearer(R1_TOKEN))).status_code == 200
        # the digest is what the server keeps, never a credential
        assert (await http.get("/api/robots/R1", headers=bearer(tokens["R1"]))).status_code == 401
        export = (await http.get("/api/site/export", headers=bearer(srv.admin_token))).text
        assert R1_TOKEN not in export and tokens["R1"] in export
        # an exported site imports again and the robot still signs in
        imported = await http.post(
            "/api/site/import",
            content=export.encode(),
            headers=bearer(srv.admin_token) | {"Content-Type": "application/yaml"},
        )
        assert imported.status_code == 200
        assert (await http.get("/api/robots/R1", headers=bearer(R1_TOKEN))).status_code == 200
    raw = database_bytes(tmp_path)
    assert b"robot-R1-demo-token" not in raw and token_digest(R1_TOKEN).encode() in raw
    with sqlite3.connect(tmp_path / "guidebot.db") as db:  # the file is a real database
        assert db.execute("select count(*) from site").fetchone() == (1,)


def database_bytes(folder: Path) -> bytes:
    return b"".join(p.read_bytes() for p in folder.glob("guidebot.db*"))


def test_production_refuses_default_or_weak_secrets_and_says_which() -> None:
    with pytest.raises(ValidationError) as missing:
        Settings(environment="production")
    text = describe_errors(missing.value)
    assert "GUIDEBOT_ADMIN_TOKEN is missing" in text
    weak = [StaticToken(token="panel-short1", name="kiosk", role="panel")]
    with pytest.raises(ValidationError) as short:
        Settings(environment="staging", admin_token="a-real-secret-admin-42", tokens=weak)
    text = describe_errors(short.value)
    assert "'kiosk'" in text and "shorter than 16" in text
    assert "panel-short1" not in text and "a-real-secret-admin-42" not in text  # no secrets
    ok = Settings(environment="production", admin_token="a-real-secret-admin-42")
    assert not ok.development


async def test_production_start_refuses_the_demo_sites_robot_tokens(tmp_path: Path) -> None:
    settings = server_settings(tmp_path).model_copy(
        update={
            "environment": "production",
            "admin_token": "a-real-secret-admin-42",
            "tokens": [],
        }
    )
    app = create_app(settings)
    with pytest.raises(InsecureSite) as refused:
        async with app.router.lifespan_context(app):
            pass
    text = str(refused.value)
    assert "refusing to start with environment='production'" in text
    assert "robot 'R1': its token is a default published with GuideBot" in text
    assert R1_TOKEN not in text


async def test_task_creation_is_rate_limited_per_requester(tmp_path: Path) -> None:
    settings = server_settings(tmp_path).model_copy(
        update={"task_requests_per_minute": 1.0, "task_request_burst": 2}
    )
    async with running_server(settings) as srv, httpx.AsyncClient(base_url=srv.url) as http:
        for _ in range(2):
            ok = await http.post("/api/tasks", json=GROUND, headers=bearer(PANEL_TOKEN))
            assert ok.status_code == 201
        refused = await http.post("/api/tasks", json=GROUND, headers=bearer(PANEL_TOKEN))
        assert refused.status_code == 429
        assert "too many task requests from panel-1" in refused.json()["detail"]
        assert int(refused.headers["Retry-After"]) > 0
        # nothing was queued for the refused request; others are not affected, staff not limited
        listed = (await http.get("/api/tasks", headers=bearer(OPERATOR_TOKEN))).json()
        assert listed["total"] == 2
        robot = await http.post("/api/tasks", json=GROUND, headers=bearer(R1_TOKEN))
        assert robot.status_code == 201
        for _ in range(3):
            staff = await http.post("/api/tasks", json=GROUND, headers=bearer(OPERATOR_TOKEN))
            assert staff.status_code == 201


async def test_failed_sign_ins_are_limited_per_address(tmp_path: Path) -> None:
    settings = server_settings(tmp_path).model_copy(
        update={"sign_in_failures_per_minute": 1.0, "sign_in_failure_burst": 3}
    )
    async with running_server(settings) as srv, httpx.AsyncClient(base_url=srv.url) as http:
        assert (await http.get("/api/me", headers=bearer(PANEL_TOKEN))).json() == {
            "name": "panel-1",
            "role": "panel",
        }
        for i in range(3):
            wrong = await http.get("/api/me", headers=bearer(f"guess-number-{i}"))
            assert wrong.status_code == 401
        locked = await http.get("/api/me", headers=bearer(PANEL_TOKEN))  # even the right one
        assert locked.status_code == 429 and "too many failed sign-in" in locked.json()["detail"]
        assert int(locked.headers["Retry-After"]) > 0
        url = f"{srv.ws_url}?token={PANEL_TOKEN}"
        async with websockets.connect(url, proxy=None) as ws:
            with pytest.raises(ConnectionClosed) as closed:
                await asyncio.wait_for(ws.recv(), WAIT)
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 4029


async def test_bodies_are_limited_and_params_strict_without_echoing_input(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    async with running_server(server_settings(tmp_path)) as srv:
        async with httpx.AsyncClient(base_url=srv.url, headers=bearer(OPERATOR_TOKEN)) as http:
            huge = {"kind": "tour", "params": {"tour": "ground", "x": "y" * 200_000}}
            too_large = await http.post("/api/tasks", json=huge)
            assert too_large.status_code == 413
            assert too_large.json()["detail"] == (
                "request body too large: the limit is 65536 bytes"
            )
            typo = await http.post("/api/tasks", json={"kind": "tour", "params": {"tuor": "x"}})
            assert typo.status_code == 422
            assert "expected: tour" in orjson.dumps(typo.json()).decode()
            secret = "s3cret-in-a-field-" + "z" * 80  # too long for an id: refused, not echoed
            bad = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": secret}})
            assert bad.status_code == 422 and secret not in bad.text
            wrong_type = await http.post("/api/tasks", json={"kind": "tour", "priority": secret})
            assert wrong_type.status_code == 422 and secret not in wrong_type.text
            listed = (await http.get("/api/tasks")).json()
            assert listed["total"] == 0  # nothing of it was stored
    logged = "\n".join(r.getMessage() for r in caplog.records)
    assert OPERATOR_TOKEN not in logged and secret not in logged


async def test_status_codes_are_consistent_and_history_survives_a_restart(
    tmp_path: Path,
) -> None:
    settings = server_settings(tmp_path)
    staff = bearer(OPERATOR_TOKEN)
    async with running_server(settings) as srv:
        async with httpx.AsyncClient(base_url=srv.url, headers=staff) as http:
            unknown_robot = {"robot": "R9"}
            created = await http.post("/api/tasks", json=GROUND | unknown_robot)
            assert created.status_code == 422 and "unknown robot 'R9'" in created.json()["detail"]
            task = (await http.post("/api/tasks", json=GROUND)).json()
            moved = await http.post(f"/api/tasks/{task['id']}/reassign", json=unknown_robot)
            assert moved.status_code == 422 and "unknown robot 'R9'" in moved.json()["detail"]
            assert (await http.post("/api/tasks/nope/cancel")).status_code == 404
            ids = [(await http.post("/api/tasks", json=GROUND)).json()["id"] for _ in range(4)]
            for task_id in [task["id"], *ids[:2]]:
                assert (await http.post(f"/api/tasks/{task_id}/cancel")).status_code == 200
            again = await http.post(f"/api/tasks/{task['id']}/cancel")
            assert again.status_code == 409 and "already cancelled" in again.json()["detail"]
    async with running_server(settings) as srv:
        async with httpx.AsyncClient(base_url=srv.url, headers=staff) as http:
            got = await http.get(f"/api/tasks/{task['id']}")
            assert got.status_code == 200 and got.json()["state"] == "cancelled"
            again = await http.post(f"/api/tasks/{task['id']}/cancel")
            assert again.status_code == 409 and "already cancelled" in again.json()["detail"]
            priority = await http.post(f"/api/tasks/{task['id']}/priority", json={"priority": 9})
            assert priority.status_code == 409
            cancelled = (await http.get("/api/tasks", params={"state": "cancelled"})).json()
            assert cancelled["total"] == 3
            assert {t["id"] for t in cancelled["tasks"]} == {task["id"], *ids[:2]}
            page = (
                await http.get(
                    "/api/tasks",
                    params={"state": "cancelled", "limit": 2, "offset": 2},
                )
            ).json()
            assert page["total"] == 3 and len(page["tasks"]) == 1
            everything = (await http.get("/api/tasks", params={"include_internal": False})).json()
            queued = [t for t in everything["tasks"] if t["state"] == "queued"]
            assert [t["id"] for t in queued] == ids[2:]  # queued first, in service order
            assert everything["total"] == 5
            mine = (await http.get("/api/tasks", headers=bearer(PANEL_TOKEN))).json()
            assert mine == {"total": 0, "tasks": []}
