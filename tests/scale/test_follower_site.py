"""A follower takes the robots' tokens of a site edited on the leader (docs/scaling.md)."""

from __future__ import annotations

import asyncio
import logging
from pathlib import Path
from types import SimpleNamespace

import httpx
import orjson
import pytest
import websockets

from backend import cluster
from backend.auth import TokenStore
from backend.db import DbStore, make_engine, make_sessionmaker, migrate
from backend.hub import Hub
from bench.servers import ADMIN_TOKEN, DEMO, ServerProcess, wait_until
from guidebot.site.yamlio import load_site_file

NEW_TOKEN = "robot-R3-new-token-after-the-edit"


async def _refused(server: ServerProcess, token: str) -> bool:
    """The server closes the connection instead of welcoming the client."""
    try:
        async with websockets.connect(f"ws://127.0.0.1:{server.port}/ws?token={token}") as ws:
            first = orjson.loads(await asyncio.wait_for(ws.recv(), 20))
    except (websockets.InvalidStatus, websockets.ConnectionClosed):
        return True
    assert first["type"] == "welcome", first
    return False


async def test_a_follower_takes_new_robot_tokens_after_a_site_edit(
    pair: list[ServerProcess],
) -> None:
    alpha, beta = pair

    async def alpha_serves() -> bool:
        health = await alpha.health()
        return bool(health and health["cluster"]["serving"])

    await wait_until(alpha_serves, 60, "alpha to lead")
    assert not await _refused(beta, "robot-R3-demo-token")  # the token at beta's start
    site = load_site_file(DEMO).model_dump(mode="json")
    for entry in site["robots"]:
        if entry["name"] == "R3":
            entry["token"] = NEW_TOKEN
    async with httpx.AsyncClient(headers={"Authorization": f"Bearer {ADMIN_TOKEN}"}) as http:
        answer = await http.put(f"{alpha.url}/api/site", json=site, timeout=30)
    assert answer.status_code == 200, answer.text

    async def new_token_works() -> bool:
        return not await _refused(beta, NEW_TOKEN)

    await wait_until(new_token_works, 20, "beta to accept R3's new token")
    assert await _refused(beta, "robot-R3-demo-token"), "the replaced token still works on beta"


@pytest.mark.parametrize("token", ["", "robot-R9-unknown-token"])
async def test_a_follower_refuses_unknown_robot_tokens(
    pair: list[ServerProcess], token: str
) -> None:
    assert await _refused(pair[1], token)


async def test_a_follower_started_before_any_site_takes_the_tokens_once_one_is_stored(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A follower may start before the first leader has migrated the database: one warning
    with the driver's reason (not SQLAlchemy's statement dump), then it looks again until a
    site is stored, and the site's robots may connect to it."""
    monkeypatch.setattr(cluster, "FOLLOWER_RETRY_S", 0.05)
    url = f"sqlite+aiosqlite:///{tmp_path / 'guidebot.db'}"
    app = SimpleNamespace(state=SimpleNamespace(tokens=TokenStore()))
    follower = cluster._FollowerTokens(app, url)  # type: ignore[arg-type]
    hub = Hub()
    with caplog.at_level(logging.WARNING, logger="backend.cluster"):
        assert not await follower.load()
        stop = follower.watch(hub, SimpleNamespace(leading=False))  # type: ignore[arg-type]
        try:
            await asyncio.sleep(0.2)  # several more tries, no more warnings
            engine = make_engine(url)
            await migrate(engine)
            await DbStore(make_sessionmaker(engine)).save_site(
                load_site_file(DEMO).model_dump(mode="json")
            )
            await engine.dispose()

            async def loaded() -> bool:
                return follower.loaded

            await wait_until(loaded, 10, "the follower to take the stored site")
        finally:
            stop()
            hub.close()
    [record] = [r for r in caplog.records if r.name == "backend.cluster"]
    assert record.getMessage() == (
        "cluster: no site in the database yet (no such table: site): robots connect to the leader"
    )
    principal = app.state.tokens.lookup("robot-R3-demo-token")
    assert principal is not None and principal.name == "R3"
