"""A person signed in by their session cookie on several server processes (docs/scaling.md,
docs/security.md "Hub links"): the session lives in the shared PostgreSQL, so a follower's hub
takes the cookie as the leader's does, and closes the link when the session ends on the
leader (disabled, signed out) within the sweep. Real processes, real PostgreSQL and Redis."""

from __future__ import annotations

import asyncio
from typing import Any

import httpx
import orjson
import pytest
import websockets
from websockets.exceptions import ConnectionClosed

from backend.accounts.cookies import CSRF_HEADER, SESSION_COOKIE
from bench.servers import ADMIN_TOKEN, ServerProcess

PASSWORD = "Tall-ships sail at dawn 7"
AUTH = {"Authorization": f"Bearer {ADMIN_TOKEN}"}
WAIT = 20.0


async def signed_in(leader: ServerProcess, name: str, role: str) -> tuple[str, str]:
    """An account made with the admin token; its session cookie and CSRF token (the cookie is
    Secure outside development, so it is sent by hand over the tests' plain HTTP)."""
    async with httpx.AsyncClient(base_url=leader.url, timeout=30) as http:
        made = await http.post(
            "/api/accounts", json={"name": name, "role": role, "password": PASSWORD}, headers=AUTH
        )
        assert made.status_code == 201, made.text
        answer = await http.post("/api/session", json={"name": name, "password": PASSWORD})
        assert answer.status_code == 200, answer.text
        return answer.cookies[SESSION_COOKIE], answer.json()["csrf"]


async def hub_link(server: ServerProcess, cookie: str) -> Any:
    """A page's hub link by cookie alone, from the server's own origin; open once welcomed."""
    ws = await websockets.connect(
        f"ws://127.0.0.1:{server.port}/ws",
        additional_headers={"Cookie": f"{SESSION_COOKIE}={cookie}"},
        origin=server.url,  # type: ignore[arg-type]
    )
    first = orjson.loads(await asyncio.wait_for(ws.recv(), WAIT))
    assert first["type"] == "welcome", first
    return ws


async def closed_with(ws: Any) -> int:
    with pytest.raises(ConnectionClosed) as closed:
        while True:
            await asyncio.wait_for(ws.recv(), WAIT)
    assert closed.value.rcvd is not None
    return closed.value.rcvd.code


async def test_a_cookie_signs_a_page_in_on_a_follower_s_hub_until_the_session_ends(
    pair: list[ServerProcess],
) -> None:
    alpha, beta = pair
    await alpha.until(alpha.leads, "alpha to lead")
    cookie, _ = await signed_in(alpha, "ada", "operator")
    other, _ = await signed_in(alpha, "bob", "viewer")

    ws = await hub_link(beta, cookie)  # the follower reads the session from PostgreSQL
    await ws.send(orjson.dumps({"type": "ping", "payload": {}, "id": "p"}).decode())
    pong = orjson.loads(await asyncio.wait_for(ws.recv(), WAIT))
    assert pong["type"] == "pong"
    viewer = await hub_link(beta, other)

    # Disabled on the leader: the follower's link is closed by its sweep (within 5 s).
    async with httpx.AsyncClient(base_url=alpha.url, timeout=30, headers=AUTH) as http:
        answer = await http.put("/api/accounts/ada", json={"disabled": True})
        assert answer.status_code == 200, answer.text
    assert await closed_with(ws) == 4001
    refused = await websockets.connect(
        f"ws://127.0.0.1:{beta.port}/ws",
        additional_headers={"Cookie": f"{SESSION_COOKIE}={cookie}"},
        origin=beta.url,  # type: ignore[arg-type]
    )
    assert await closed_with(refused) == 4001  # the ended session opens nothing there either

    # Signed out on the leader: the same.
    async with httpx.AsyncClient(base_url=alpha.url, timeout=30) as http:
        mine = {"Cookie": f"{SESSION_COOKIE}={other}"}
        csrf = (await http.get("/api/session", headers=mine)).json()["csrf"]
        bye = await http.delete("/api/session", headers={**mine, CSRF_HEADER: csrf})
        assert bye.status_code == 204, bye.text
    assert await closed_with(viewer) == 4001
