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

from backend.cluster import _FollowerTokens
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


async def test_a_follower_before_any_schema_says_so_in_one_line(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A follower may start before the first leader has migrated the database: one warning
    with the driver's reason, not SQLAlchemy's statement dump."""
    app = SimpleNamespace(state=SimpleNamespace(tokens=None))
    follower = _FollowerTokens(app, f"sqlite+aiosqlite:///{tmp_path / 'empty.db'}")  # type: ignore[arg-type]
    with caplog.at_level(logging.WARNING, logger="backend.cluster"):
        await follower.load()
    [record] = [r for r in caplog.records if r.name == "backend.cluster"]
    assert record.getMessage() == (
        "cluster: no site in the database yet (no such table: site): robots connect to the leader"
    )
    assert follower.known == {}
