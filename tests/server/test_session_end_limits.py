"""The end of a session is not a failed sign-in (docs/security.md, "Rate limits"): a console
whose session ends with requests in flight gets a 401 for each, and none of them counts toward
the address's budget of failed sign-ins; a wrong token still does. Against a real server."""

from __future__ import annotations

import asyncio
import time

import httpx

from backend.accounts.cookies import SESSION_COOKIE
from backend.auth import Role, token_digest
from backend.testing import RunningServer

from .conftest import OPERATOR_TOKEN

PASSWORD = "Tall-ships sail at dawn 7"
IN_FLIGHT = 12
"""More requests than the address's burst of failed sign-ins (10): each one counted, the next
sign-in met 429."""


def frozen(server: RunningServer) -> None:
    """The buckets do not refill during the test (a refill would hide a spent budget)."""
    now = time.monotonic()
    server.app.state.auth.failures.clock = server.app.state.accounts.lockouts.clock = lambda: now


async def sign_in(http: httpx.AsyncClient) -> httpx.Response:
    return await http.post("/api/session", json={"name": "ada", "password": PASSWORD})


async def test_requests_of_an_expired_session_do_not_count_as_failed_sign_ins(
    server: RunningServer,
) -> None:
    accounts = server.app.state.accounts
    await accounts.create("ada", Role.OPERATOR.value, PASSWORD, by="test", address="test")
    frozen(server)
    async with httpx.AsyncClient(base_url=server.url, timeout=10) as http:
        signed = await sign_in(http)
        assert signed.status_code == 200, signed.text
        cookie = http.cookies[SESSION_COOKIE]
        # The session ends by itself (2 hours without use) while the console is open.
        await accounts.store.change_session(token_digest(cookie), seen_at=-(accounts.idle_s + 1))
        answers = await asyncio.gather(*(http.get("/api/robots") for _ in range(IN_FLIGHT)))
        assert [a.status_code for a in answers] == [401] * IN_FLIGHT
        assert server.app.state.auth.failures.wait_time("127.0.0.1") == 0
        # The person signs in again at once, twice (another tab): no 429.
        for _ in range(2):
            again = await sign_in(http)
            assert again.status_code == 200, again.text


async def test_requests_without_any_credential_do_not_count_but_wrong_tokens_do(
    server: RunningServer,
) -> None:
    frozen(server)
    async with httpx.AsyncClient(base_url=server.url, timeout=10) as http:
        answers = await asyncio.gather(*(http.get("/api/robots") for _ in range(IN_FLIGHT)))
        assert [a.status_code for a in answers] == [401] * IN_FLIGHT
        staff = {"Authorization": f"Bearer {OPERATOR_TOKEN}"}
        assert (await http.get("/api/robots", headers=staff)).status_code == 200
        # A wrong token is a guess: ten of them spend the budget, then even the right one waits.
        for i in range(10):
            wrong = await http.get("/api/robots", headers={"Authorization": f"Bearer guess-{i}"})
            assert wrong.status_code == 401
        assert (await http.get("/api/robots", headers=staff)).status_code == 429
