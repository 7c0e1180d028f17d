"""People's accounts (backend/accounts, docs/security.md "Accounts"): password sign-in, the
session cookie, CSRF, sign-out, expiry, the admins' accounts API, the audit trail, and the
hostile cases of issue 40 against a real server."""

from __future__ import annotations

import asyncio
import contextlib
import csv
import io
import logging
import sqlite3
import time
from collections.abc import AsyncIterator
from pathlib import Path

import httpx
import orjson
import pytest
import websockets
from click.testing import CliRunner
from websockets.exceptions import ConnectionClosed

from backend.accounts import component
from backend.accounts.cli import users
from backend.accounts.cookies import CSRF_HEADER, SESSION_COOKIE
from backend.accounts.store import AccountStore
from backend.auth import Role
from backend.testing import RunningServer, running_server

from .conftest import server_settings
from .test_permissions import ROBOT_NAME, concrete, rest_table

PASSWORD = "Tall-ships sail at dawn 7"
OTHER = "Quiet galleries after six"
WAIT = 10.0
SIGNING_OUT = {("DELETE", "/api/session"), ("POST", "/api/session/everywhere")}


@pytest.fixture
async def server(tmp_path: Path) -> AsyncIterator[RunningServer]:
    async with running_server(server_settings(tmp_path)) as srv:
        yield srv


async def make(server: RunningServer, name: str, role: Role, password: str = PASSWORD) -> None:
    await server.app.state.accounts.create(name, role.value, password, by="test", address="test")


@contextlib.asynccontextmanager
async def signed_in(
    server: RunningServer, name: str, password: str = PASSWORD
) -> AsyncIterator[tuple[httpx.AsyncClient, str]]:
    """A browser-like client holding the session cookie, and its CSRF token."""
    async with httpx.AsyncClient(base_url=server.url, timeout=10) as http:
        answer = await http.post("/api/session", json={"name": name, "password": password})
        assert answer.status_code == 200, answer.text
        yield http, answer.json()["csrf"]


async def test_a_person_signs_in_with_a_password_into_an_httponly_strict_cookie(
    server: RunningServer,
) -> None:
    await make(server, "ada", Role.OPERATOR)
    async with httpx.AsyncClient(base_url=server.url, timeout=10) as http:
        answer = await http.post("/api/session", json={"name": "ada", "password": PASSWORD})
        assert answer.status_code == 200
        cookie = answer.headers["set-cookie"].lower()
        assert "httponly" in cookie and "samesite=strict" in cookie and "path=/" in cookie
        assert "secure" not in cookie  # development: plain http on the LAN demo
        me = (await http.get("/api/session")).json()
        assert me["signed_in"] is True and me["name"] == "ada" and me["role"] == "operator"
        assert me["csrf"] == answer.json()["csrf"]
        assert (await http.get("/api/robots")).status_code == 200  # operator's route
        assert (await http.get("/api/me")).json() == {"name": "ada", "role": "operator"}
    accounts = await AccountStore(server.app.state.store.sessionmaker).get("ada")
    assert accounts is not None and accounts.last_sign_in is not None


async def test_the_cookie_is_secure_outside_development(server: RunningServer) -> None:
    """(A production server refuses the demo site's robot tokens: the setting is switched on
    the running one.)"""
    await make(server, "ada", Role.OPERATOR)
    server.app.state.settings.environment = "staging"
    async with httpx.AsyncClient(base_url=server.url, timeout=10) as http:
        answer = await http.post("/api/session", json={"name": "ada", "password": PASSWORD})
    assert "secure" in answer.headers["set-cookie"].lower()


async def test_a_state_changing_request_without_the_csrf_token_is_refused(
    server: RunningServer,
) -> None:
    await make(server, "ada", Role.ADMIN)
    async with signed_in(server, "ada") as (http, csrf):
        body = {"name": "bob", "role": "viewer", "password": OTHER}
        for headers in ({}, {CSRF_HEADER: "x" * 43}):
            refused = await http.post("/api/accounts", json=body, headers=headers)
            assert refused.status_code == 403, refused.text
            assert "CSRF" in refused.json()["detail"]
        assert await server.app.state.accounts.store.get("bob") is None
        made = await http.post("/api/accounts", json=body, headers={CSRF_HEADER: csrf})
        assert made.status_code == 201, made.text
        assert (await http.delete("/api/session")).status_code == 403  # sign-out too
        assert (await http.get("/api/session")).json()["signed_in"] is True


async def test_every_state_changing_route_refuses_a_session_without_the_csrf_token(
    server: RunningServer,
) -> None:
    """Every operation of docs/server.md's table but reads and the public ones, called by an
    admin's session without ``X-CSRF-Token``: 403 naming CSRF, before anything is done."""
    await make(server, "ada", Role.ADMIN)
    wrong = []
    checked = 0
    async with signed_in(server, "ada") as (http, _):
        for row in rest_table():
            if row.rule == "public":
                continue
            for method, path in row.operations:
                if method == "GET":
                    continue
                checked += 1
                answer = await http.request(method, concrete(path), json={})
                if answer.status_code != 403 or "CSRF" not in answer.text:
                    wrong.append(f"{method} {path} -> {answer.status_code}")
    assert wrong == []
    assert checked > 40


async def test_a_cookie_replayed_after_sign_out_is_refused(server: RunningServer) -> None:
    await make(server, "ada", Role.OPERATOR)
    async with signed_in(server, "ada") as (http, csrf):
        stolen = http.cookies[SESSION_COOKIE]
        assert (await http.delete("/api/session", headers={CSRF_HEADER: csrf})).status_code == 204
        assert SESSION_COOKIE not in http.cookies
    async with httpx.AsyncClient(
        base_url=server.url, cookies={SESSION_COOKIE: stolen}, timeout=10
    ) as replay:
        assert (await replay.get("/api/robots")).status_code == 401
        assert (await replay.get("/api/session")).json()["signed_in"] is False


async def test_sign_out_everywhere_ends_every_session_of_the_account(
    server: RunningServer,
) -> None:
    await make(server, "ada", Role.OPERATOR)
    async with signed_in(server, "ada") as (first, csrf), signed_in(server, "ada") as (second, _):
        answer = await first.post("/api/session/everywhere", headers={CSRF_HEADER: csrf})
        assert answer.json() == {"ended": 2}
        assert (await second.get("/api/robots")).status_code == 401
        assert (await first.get("/api/robots")).status_code == 401


async def test_an_idle_session_and_an_old_one_expire(server: RunningServer) -> None:
    await make(server, "ada", Role.OPERATOR)
    service = server.app.state.accounts
    for column in ("seen_at", "created_at"):
        async with signed_in(server, "ada") as (http, _):
            session = await service.session(http.cookies[SESSION_COOKIE])
            assert session is not None
            age = (service.idle_s if column == "seen_at" else service.max_s) + 1
            await service.store.change_session(session.digest, **{column: -age})
            assert (await http.get("/api/robots")).status_code == 401, column


async def test_sign_in_failures_are_limited_per_address_and_per_account(
    server: RunningServer,
) -> None:
    """Ten wrong passwords, then even the right one is 429 with Retry-After; a wrong name
    and a wrong password get the same answer."""
    await make(server, "ada", Role.OPERATOR)
    now = time.monotonic()  # the buckets do not refill while the slow hashes run
    server.app.state.auth.failures.clock = server.app.state.accounts.lockouts.clock = lambda: now
    async with httpx.AsyncClient(base_url=server.url, timeout=10) as http:
        answers = []
        for name in ["nobody"] + ["ada"] * 9:
            answer = await http.post("/api/session", json={"name": name, "password": OTHER})
            answers.append((answer.status_code, answer.json()["detail"]))
        assert set(answers) == {(401, "wrong account name or password")}
        right = await http.post("/api/session", json={"name": "ada", "password": PASSWORD})
        assert right.status_code == 429 and int(right.headers["retry-after"]) >= 1
        token = await http.get("/api/robots", headers={"Authorization": "Bearer wrong"})
        assert token.status_code == 429  # the same budget as the token sign-in
        server.app.state.auth.failures.forget("127.0.0.1")  # as if from another address
        tenth = await http.post("/api/session", json={"name": "ada", "password": OTHER})
        assert tenth.status_code == 401
        locked = await http.post("/api/session", json={"name": "ada", "password": PASSWORD})
        assert locked.status_code == 429  # the account's own budget is spent


@pytest.mark.parametrize(
    ("password", "why"),
    [
        ("short-one", "at least 12"),
        ("Password12345", "common passwords"),
        ("aaaaaaaaaaaaaaa", "too few"),
        ("bob-the-builder-99", "account's name"),
    ],
)
async def test_a_weak_password_is_refused(server: RunningServer, password: str, why: str) -> None:
    admin = {"Authorization": f"Bearer {server.admin_token}"}
    async with httpx.AsyncClient(base_url=server.url, timeout=10, headers=admin) as http:
        body = {"name": "bob", "role": "viewer", "password": password}
        answer = await http.post("/api/accounts", json=body)
    assert answer.status_code == 422 and why in answer.json()["detail"]


@pytest.mark.parametrize(
    "role", [Role.VIEWER, Role.AUTHOR, Role.INSTALLER, Role.OPERATOR, Role.ADMIN]
)
async def test_a_person_is_refused_every_route_the_docs_leave_out_for_their_role(
    server: RunningServer, role: Role
) -> None:
    """Every operation of docs/server.md's table, called with a session of each person's role
    (and its CSRF token): 403 exactly where the role's column says "—" (a viewer on every
    operator route among them). Bodies are an empty object: nothing is changed."""
    await make(server, "pat", role)
    wrong = []
    async with signed_in(server, "pat") as (http, csrf):
        for row in rest_table():
            for method, path in row.operations:
                if (method, path) in SIGNING_OUT:
                    continue  # would sign the person out: checked elsewhere
                url = concrete(path)
                body = {} if method != "GET" else None
                answer = await http.request(method, url, json=body, headers={CSRF_HEADER: csrf})
                if (answer.status_code == 403) is (role in row.roles):
                    wrong.append(f"{method} {url} -> {answer.status_code}")
        assert (await http.get("/api/session")).json()["signed_in"]  # still signed in
    assert wrong == []
    assert ROBOT_NAME  # the table's paths name the demo's robot


async def test_disabling_an_account_ends_its_sessions_and_hub_links_at_once(
    server: RunningServer,
) -> None:
    await make(server, "ada", Role.OPERATOR)
    await make(server, "root", Role.ADMIN)
    async with signed_in(server, "ada") as (http, _), signed_in(server, "root") as (admin, csrf):
        cookie = f"{SESSION_COOKIE}={http.cookies[SESSION_COOKIE]}"
        ws = await websockets.connect(server.ws_url, additional_headers={"Cookie": cookie})
        welcome = orjson.loads(await asyncio.wait_for(ws.recv(), WAIT))
        assert welcome["type"] == "welcome"
        answer = await admin.put(
            "/api/accounts/ada", json={"disabled": True}, headers={CSRF_HEADER: csrf}
        )
        assert answer.status_code == 200 and answer.json()["disabled"] is True
        with pytest.raises(ConnectionClosed) as closed:
            while True:
                await asyncio.wait_for(ws.recv(), WAIT)
        await ws.close()
        assert closed.value.rcvd is not None and closed.value.rcvd.code == 4001
        assert (await http.get("/api/robots")).status_code == 401
        again = await http.post("/api/session", json={"name": "ada", "password": PASSWORD})
        assert again.status_code == 403 and again.json()["detail"] == "this account is disabled"
        last = await admin.put(
            "/api/accounts/root", json={"disabled": True}, headers={CSRF_HEADER: csrf}
        )
        assert last.status_code == 409  # the last enabled admin


async def test_a_cross_site_websocket_does_not_ride_on_the_cookie(server: RunningServer) -> None:
    await make(server, "ada", Role.OPERATOR)
    async with signed_in(server, "ada") as (http, _):
        cookie = f"{SESSION_COOKIE}={http.cookies[SESSION_COOKIE]}"
        async with websockets.connect(
            server.ws_url, additional_headers={"Cookie": cookie}, origin="http://evil.example"
        ) as ws:  # type: ignore[arg-type]
            with pytest.raises(ConnectionClosed) as closed:
                await asyncio.wait_for(ws.recv(), WAIT)
    assert closed.value.rcvd is not None and closed.value.rcvd.code == 4001


async def test_people_s_actions_are_in_the_event_log_by_person_and_exported(
    server: RunningServer,
) -> None:
    await make(server, "ada", Role.OPERATOR)
    await make(server, "root", Role.ADMIN)
    async with signed_in(server, "ada") as (http, csrf):
        paused = await http.post(
            "/api/fleet/pause", json={"reason": "gallery cleaning"}, headers={CSRF_HEADER: csrf}
        )
        assert paused.status_code == 200, paused.text
        events = (await http.get("/api/events", params={"person": "ada"})).json()["events"]
    kinds = [e["kind"] for e in events]
    assert kinds == ["signed_in", "staff_action"]
    action = events[1]["data"]
    assert action == {
        "account": "ada",
        "role": "operator",
        "address": "127.0.0.1",
        "method": "POST",
        "path": "/api/fleet/pause",
        "status": 200,
    }
    async with signed_in(server, "root") as (admin, admin_csrf):
        export = await admin.get("/api/audit/export", params={"person": "ada"})
        assert export.status_code == 200 and export.headers["content-type"].startswith("text/csv")
        rows = list(csv.DictReader(io.StringIO(export.text)))
        assert [r["kind"] for r in rows] == kinds
        assert {r["account"] for r in rows} == {"ada"} and rows[0]["address"] == "127.0.0.1"
        viewer = await admin.post(
            "/api/accounts",
            json={"name": "vic", "role": "viewer", "password": OTHER},
            headers={CSRF_HEADER: admin_csrf},
        )
        assert viewer.status_code == 201
        mine = (await admin.get("/api/events", params={"person": "root"})).json()["events"]
    assert [e["kind"] for e in mine] == ["signed_in", "account_changed"]
    assert mine[1]["data"]["target"] == "vic" and mine[1]["data"]["address"] == "127.0.0.1"


async def test_no_password_cookie_or_csrf_token_reaches_a_log_line_or_an_event(
    server: RunningServer, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    await make(server, "ada", Role.ADMIN)
    async with httpx.AsyncClient(base_url=server.url, timeout=10) as bad:
        await bad.post("/api/session", json={"name": "ada", "password": OTHER})
    async with signed_in(server, "ada") as (http, csrf):
        cookie = http.cookies[SESSION_COOKIE]
        await http.post("/api/fleet/pause", json={}, headers={CSRF_HEADER: csrf})
        await http.post("/api/accounts", json={"name": "bob", "role": "viewer", "password": "x"})
        await http.delete("/api/session", headers={CSRF_HEADER: csrf})
    events = await server.app.state.store.events(limit=1000)
    secrets_ = (PASSWORD, OTHER, cookie, csrf)
    server_side = [r for r in caplog.records if not r.name.startswith(("httpx", "httpcore"))]
    text = "\n".join(r.getMessage() for r in server_side) + orjson.dumps(events).decode()
    assert [s for s in secrets_ if s in text] == []
    assert {"signed_in", "sign_in_failed", "signed_out", "staff_action"} <= {
        e["kind"] for e in events
    }


def test_guidebot_users_add_creates_the_first_admin_and_prints_nothing_secret(
    tmp_path: Path,
) -> None:
    url = f"sqlite+aiosqlite:///{tmp_path / 'guidebot.db'}"
    runner = CliRunner()
    added = runner.invoke(
        users, ["add", "alice", "--db-url", url], input=f"{PASSWORD}\n{PASSWORD}\n"
    )
    assert added.exit_code == 0, added.output
    assert PASSWORD not in added.output
    assert added.output.strip().endswith("account alice (admin) created")
    weak = runner.invoke(
        users, ["add", "bob", "--password-stdin", "--db-url", url], input="password\n"
    )
    assert weak.exit_code == 1 and "at least 12" in weak.output
    listed = runner.invoke(users, ["list", "--db-url", url])
    assert listed.output.startswith("alice\tadmin\tlast sign-in never")


async def test_a_passkey_answer_that_is_not_accepted_counts_as_a_failed_sign_in(
    server: RunningServer,
) -> None:
    """A made-up credential, or a real challenge answered twice: 401 like a wrong password,
    and the address's budget shrinks (the real passkey flow: tests/web/test_accounts.py)."""
    async with httpx.AsyncClient(base_url=server.url, timeout=10) as http:
        start = (await http.post("/api/session/passkey/options", json={})).json()
        assert start["options"]["rpId"] == "127.0.0.1"
        assert start["options"]["userVerification"] == "required"
        bogus = {"id": "AAAA", "rawId": "AAAA", "type": "public-key", "response": {}}
        for challenge in (start["challenge_id"], start["challenge_id"], "made-up"):
            answer = await http.post(
                "/api/session/passkey", json={"challenge_id": challenge, "credential": bogus}
            )
            assert answer.status_code == 401, answer.text
        for _ in range(7):
            await http.post("/api/session/passkey", json={"challenge_id": "x", "credential": bogus})
        limited = await http.post("/api/session/passkey/options", json={})
        assert limited.status_code == 429
        token = {"Authorization": f"Bearer {server.admin_token}"}
    server.app.state.auth.failures.forget("127.0.0.1")
    async with httpx.AsyncClient(base_url=server.url, timeout=10, headers=token) as admin:
        refused = await admin.post("/api/session/passkeys/options", json={})
    assert refused.status_code == 409  # a token has no account to add a passkey to
    events = await server.app.state.store.events(kind="sign_in_failed", limit=100)
    assert {e["data"]["why"] for e in events} == {"passkey"}


def test_an_unknown_role_in_the_oidc_roles_stops_the_start_naming_it(tmp_path: Path) -> None:
    """GUIDEBOT_OIDC_ROLES with a role no person has: the start is refused (exit 2) by the
    settings' validation, naming the variable, the group, the bad role and the roles there
    are; no traceback."""
    from backend.server_cli import server as server_command

    result = CliRunner().invoke(
        server_command,
        ["--db", f"sqlite+aiosqlite:///{tmp_path}/x.db"],
        env={
            "GUIDEBOT_ENVIRONMENT": "development",
            "GUIDEBOT_OIDC_ISSUER": "http://127.0.0.1:1/idp",
            "GUIDEBOT_OIDC_ROLES": '{"front-desk": "operator", "guides": "guide"}',
        },
    )
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and result.exception is not None
    assert (
        "GUIDEBOT_OIDC_ROLES: unknown role (group 'guides' -> 'guide'): the roles are "
        "admin, author, installer, operator, viewer" in " ".join(result.output.split())
    )


async def test_a_person_removes_only_their_own_passkeys_and_an_admin_any_person_s(
    server: RunningServer,
) -> None:
    """A passkey id of another person's is 404 for a person (nothing removed); an admin's
    removal of all of a person's passkeys ends that person's sessions; audit rows for both."""
    from backend.db.models import PasskeyRow

    await make(server, "ada", Role.OPERATOR)
    await make(server, "bob", Role.VIEWER)
    await make(server, "root", Role.ADMIN)
    async with server.app.state.store.sessionmaker() as db, db.begin():
        for owner, key in (("ada", "ada-phone-0123456789"), ("bob", "bob-laptop-0123456789")):
            db.add(PasskeyRow(credential_id=key, account=owner, public_key="", created_at=1.0))
    async with signed_in(server, "ada") as (ada, csrf), signed_in(server, "root") as (root, rcsrf):
        mine = (await ada.get("/api/session/passkeys")).json()["passkeys"]
        assert [(k["id"], k["last_used"]) for k in mine] == [("ada-phone-012345", None)]
        theirs = await ada.delete(
            "/api/session/passkeys/bob-laptop-012345", headers={CSRF_HEADER: csrf}
        )
        assert theirs.status_code == 404
        listed = (await root.get("/api/accounts")).json()["accounts"]
        assert {a["name"]: a["passkeys"] for a in listed} == {"ada": 1, "bob": 1, "root": 0}
        own = await ada.delete(
            "/api/session/passkeys/ada-phone-012345", headers={CSRF_HEADER: csrf}
        )
        assert own.status_code == 204
        assert (await ada.get("/api/session")).json()["signed_in"]  # sessions stay
        async with signed_in(server, "bob") as (bob, _):
            lost = await root.delete("/api/accounts/bob/passkeys", headers={CSRF_HEADER: rcsrf})
            assert lost.json() == {"removed": 1}
            assert (await bob.get("/api/session")).json()["signed_in"] is False
        assert (await root.get("/api/accounts/bob/passkeys")).json() == {"passkeys": []}
        nobody = await root.delete("/api/accounts/nobody/passkeys", headers={CSRF_HEADER: rcsrf})
        assert nobody.status_code == 404
    events = await server.app.state.store.events(kind="account_changed", limit=100)
    removed = [
        (e["source"], e["data"]["target"], e["data"]["passkeys"])
        for e in events
        if e["data"]["change"] == "passkey_removed"
    ]
    assert removed == [("ada", "ada", 1), ("root", "bob", 1)]


async def test_audit_rows_are_kept_their_own_days_not_the_event_log_s(tmp_path: Path) -> None:
    """GUIDEBOT_AUDIT_RETENTION_DAYS (365) keeps people's sign-ins and actions past the event
    log's 30 days; older than it, they go too; 0 keeps them for ever."""
    from tests.server.test_api import eventually
    from tests.server.test_kept_across_restarts import DAY, event_kinds, seed_events

    settings = server_settings(tmp_path).model_copy(
        update={"event_retention_days": 30.0, "event_prune_every_s": 0.05}
    )
    month, years = time.time() - 40 * DAY, time.time() - 400 * DAY
    await seed_events(
        settings.db_url,
        [
            (month, "node_reached", {"robot": "R1"}),
            (month, "signed_in", {"account": "ada"}),
            (month, "staff_action", {"account": "ada"}),
            (years, "account_changed", {"account": "root"}),
        ],
    )
    async with running_server(settings) as srv:
        store = srv.app.state.store
        assert store.audit_retention_s == 365 * DAY
        await eventually(lambda: store.pruned == 2)  # the month-old node, the year-old change
        kinds = [kind for kind, _ in await event_kinds(store)]
        assert kinds[:2] == ["signed_in", "staff_action"]
    kept = settings.model_copy(update={"audit_retention_days": 0.0})
    async with running_server(kept) as srv:
        assert srv.app.state.store.audit_retention_s is None
        await srv.app.state.store.prune_events(time.time(), audit_older_than=None)
        kinds = [kind for kind, _ in await event_kinds(srv.app.state.store)]
        assert kinds[:2] == ["signed_in", "staff_action"]  # everything else went


def holder(tmp_path: Path) -> sqlite3.Connection:
    """A second real connection to the server's SQLite file. Its statements that wait for the
    lock run in a thread: on the event loop they would stop the server's writer from finishing
    the transaction they wait for."""
    return sqlite3.connect(tmp_path / "guidebot.db", isolation_level=None, check_same_thread=False)


async def test_the_session_sweep_waits_its_turn_while_another_writer_holds_sqlite(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """A 30-minute soak on SQLite logged the sweep's "database is locked" as a traceback: the
    event log's writer, in a burst of 1500 rows a second, held the write lock past the busy
    time-out. A second real connection holds it here (BEGIN IMMEDIATE): the sweep says so in
    one warning line, ends nothing, and the next one, the lock free, ends the expired session
    and keeps the live one. (The server's own sweeper is held off: the test runs the sweeps.)"""
    monkeypatch.setattr(component, "SWEEP_EVERY_S", 3600.0)
    async with running_server(server_settings(tmp_path)) as server:
        await make(server, "ada", Role.OPERATOR)
        service = server.app.state.accounts
        async with signed_in(server, "ada") as (live, _), signed_in(server, "ada") as (old, _):
            kept = await service.session(live.cookies[SESSION_COOKIE])
            ending = await service.session(old.cookies[SESSION_COOKIE])
            assert kept is not None and ending is not None
            await service.store.change_session(ending.digest, seen_at=-service.idle_s - 1)
            both = {kept.digest, ending.digest}
            other = holder(tmp_path)
            await asyncio.to_thread(other.execute, "BEGIN IMMEDIATE")  # as a burst holds it
            try:
                with caplog.at_level(logging.WARNING, logger=component.__name__):
                    assert await component.sweep_once(service, expire=True) is False
            finally:
                other.execute("ROLLBACK")
                other.close()
            said = [r for r in caplog.records if r.name == component.__name__]
            assert [r.levelno for r in said] == [logging.WARNING]
            assert said[0].exc_info is None and "database is busy" in said[0].getMessage()
            assert await service.store.live_digests(both) == both
            assert await component.sweep_once(service, expire=True) is True
            assert await service.store.live_digests(both) == {kept.digest}
            assert (await live.get("/api/session")).json()["signed_in"] is True


async def test_a_sweep_failing_for_another_reason_still_logs_its_traceback(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Only a busy database is a one-line warning: a real fault (here the sessions' table gone)
    keeps its traceback in the log."""
    monkeypatch.setattr(component, "SWEEP_EVERY_S", 3600.0)
    async with running_server(server_settings(tmp_path)) as server:
        other = holder(tmp_path)
        await asyncio.to_thread(other.execute, "ALTER TABLE account_sessions RENAME TO gone")
        try:
            with caplog.at_level(logging.WARNING, logger=component.__name__):
                assert await component.sweep_once(server.app.state.accounts, expire=True) is False
        finally:
            await asyncio.to_thread(other.execute, "ALTER TABLE gone RENAME TO account_sessions")
            other.close()
        said = [r for r in caplog.records if r.name == component.__name__]
        assert [r.levelno for r in said] == [logging.ERROR] and said[0].exc_info is not None
        assert await component.sweep_once(server.app.state.accounts, expire=True) is True
