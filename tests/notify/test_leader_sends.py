"""Only the leader sends (issue 44): two server processes' apps on one PostgreSQL (the
leadership) and one redis-server (the broker); the notifier runs on the leader only, so an
alert reaches the webhook once, and a process whose lease ran out sends nothing (the delivery
is dropped, saying why). Settings are kept in the database across a restart."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from backend.notify.service import Notifier
from backend.settings import Settings
from backend.testing import RunningServer, running_server
from bench.servers import wait_until
from tests.scale.redis import RedisServer, redis_server
from tests.server.helpers import DEMO
from tests.server.postgres import PostgresServer, postgres_server

from .conftest import settings as single_settings
from .receivers import Hooks
from .test_notify import SECRET, add, raise_alert, verify, webhook_channel


@pytest.fixture(scope="module")
def redis() -> Iterator[RedisServer]:
    with redis_server() as server:
        yield server


@pytest.fixture(scope="module")
def postgres() -> Iterator[PostgresServer]:
    with postgres_server() as pg:
        yield pg


def admin_client(server: RunningServer) -> httpx.AsyncClient:
    headers = {"Authorization": f"Bearer {server.admin_token}"}
    return httpx.AsyncClient(base_url=server.url, headers=headers, timeout=30)


async def _true(value: Any) -> Any:
    return value


async def test_a_fleet_of_two_processes_sends_once(
    postgres: PostgresServer, redis: RedisServer, hooks: Hooks
) -> None:
    database = postgres.database()

    def settings(process: str) -> Settings:
        # No fail-over here: a lease long enough that alpha keeps it while beta starts in the
        # same event loop (CI's loaded machine starved alpha's renewal past a 2 s lease, and
        # beta led). A lease running out is the may_send part below.
        return Settings(
            db_url=database,
            broker_url=redis.url,
            site=DEMO,
            leader_poll_s=0.5,
            leader_lease_s=60.0,
            process_name=process,
        )

    async with running_server(settings("alpha")) as alpha:
        leadership = alpha.app.state.leadership
        await wait_until(lambda: _true(leadership.serving), 60, "alpha to lead and serve")
        async with running_server(settings("beta")) as beta, admin_client(alpha) as admin:
            await wait_until(
                lambda: _true(alpha.app.state.broker.connected and beta.app.state.broker.connected),
                30,
                "both processes on the broker",
            )
            assert not beta.app.state.leadership.leading
            assert getattr(beta.app.state, "notify", None) is None  # a follower sends nothing
            await add(admin, webhook_channel(f"{hooks.url}/chat"))
            first = raise_alert(alpha, "R1")
            second = raise_alert(alpha, "R2")
            posts = await hooks.wait_for("/chat", 2)
            assert sorted(verify(p, SECRET)["alert"]["id"] for p in posts) == sorted(
                [first, second]
            )
            # Once the lease has run out (a paused leader), nothing is sent.
            notifier: Notifier = alpha.app.state.notify
            notifier.may_send = lambda: False
            channel = next(iter(notifier.channels))
            dropped = (await admin.post(f"/api/notifications/channels/{channel}/test")).json()
            assert dropped["status"] == "dropped" and "no longer leads" in dropped["error"]
            assert len(hooks.at("/chat")) == 2


async def test_the_settings_are_kept_across_a_restart(tmp_path: Path, hooks: Hooks) -> None:
    async with running_server(single_settings(tmp_path)) as server, admin_client(server) as admin:
        channel = await add(admin, webhook_channel(f"{hooks.url}/chat", repeat_minutes=5))
        answer = await admin.put(
            "/api/notifications/smtp",
            json={"host": "smtp.museum.example", "sender": "bot@museum.example", "password": "pw"},
        )
        assert answer.status_code == 200, answer.text
    async with running_server(single_settings(tmp_path)) as server, admin_client(server) as admin:
        shown = (await admin.get("/api/notifications")).json()
        assert [c["id"] for c in shown["channels"]] == [channel["id"]]
        assert shown["channels"][0]["repeat_minutes"] == 5
        assert shown["smtp"]["host"] == "smtp.museum.example" and shown["smtp"]["password_set"]
        tested = await admin.post(f"/api/notifications/channels/{channel['id']}/test")
        assert tested.json()["status"] == "sent"
        # The stored secret still signs (the open alerts of the new start come too).
        posts = await hooks.wait_for("/chat", 1)
        assert "test" in [verify(p, SECRET)["event"] for p in posts]
