"""The console across the end of a sign-in, in a real browser against a real server: a person
thrown out (their account disabled: the hub closes with "session ended") signs in again on the
same page and gets one working console, not a broken second one beside a stale first."""

from __future__ import annotations

import asyncio
import re
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
from playwright.async_api import expect

from backend.accounts.cookies import SESSION_COOKIE
from backend.auth import token_digest

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

PASSWORD = "Tall-ships sail at dawn 7"
SNAPSHOT_REQUESTS = 10
"""Requests of the console's reload held in flight: its snapshot's eight, the closures and the
server's health; as many as the address's burst of failed sign-ins."""

COUNT_HEADER_TIMERS = """(() => {
  // The header's server line is refreshed by a 15 s interval: count the ones still running.
  const running = new Set();
  const set = window.setInterval.bind(window);
  const clear = window.clearInterval.bind(window);
  window.setInterval = (fn, ms, ...args) => {
    const id = set(fn, ms, ...args);
    if (ms === 15000) running.add(id);
    return id;
  };
  window.clearInterval = (id) => {
    running.delete(id);
    clear(id);
  };
  window.headerTimers = () => running.size;
})();"""


async def password_sign_in(page: Any) -> None:
    await page.get_by_label("Account name").fill("ada")
    await page.get_by_label("Password").fill(PASSWORD)
    await page.get_by_role("button", name="Sign in").click()
    await page.get_by_label("Floor", exact=True).wait_for()


async def test_signing_in_again_after_the_session_ended_gives_one_working_console(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        accounts = fleet.server.app.state.accounts
        await accounts.create("ada", "operator", PASSWORD, "Ada Lovelace", by="t", address="t")
        watch = await open_page("")
        page = watch.page
        watch.expect_error(r"status of 401")  # no session yet at the first look
        await page.add_init_script(COUNT_HEADER_TIMERS)
        await page.goto(fleet.admin_url)
        await password_sign_in(page)
        who = page.locator("#who")
        sign_out = who.get_by_role("button", name="Sign out", exact=True)
        async with fleet.http() as http:
            # Once (each end costs the address a few refused requests: a second one in a row
            # met the server's limit on failed sign-ins, 429).
            for disabled in (True, False):
                reply = await http.put("/api/accounts/ada", json={"disabled": disabled})
                assert reply.status_code == 200, reply.text
            await expect(page.get_by_role("alert")).to_contain_text("session ended")
            # The form says nothing of the sign-in that ended: no name, no "Sign out".
            await expect(sign_out).to_have_count(0)
            await expect(who).not_to_contain_text("Ada Lovelace")
            await password_sign_in(page)
        # One console: the header once, one refresh timer, the live map drawing the robot.
        await expect(sign_out).to_have_count(1)
        await expect(who).to_contain_text("Server")
        assert await page.evaluate("headerTimers()") == 1
        await expect(page.get_by_role("button", name="robot R1")).to_be_visible(timeout=20_000)
        await web.open_view(page, "Robots")
        await expect(page.locator("#robot-R1")).to_contain_text("online")
        await web.axe_check(page)


async def test_a_session_that_ends_with_requests_in_flight_leaves_the_sign_in_open(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    """The session expires while the console's snapshot is on its way (a dozen requests in
    flight): each gets its 401, and the person signs in again at once, twice (this page and
    another tab) — the 401s counted as failed sign-ins, and the next sign-ins met 429."""
    async with fleet_factory(robots=0) as fleet:
        accounts = fleet.server.app.state.accounts
        await accounts.create("ada", "operator", PASSWORD, "Ada Lovelace", by="t", address="t")
        watch = await open_page("")
        page = watch.page
        watch.expect_error(r"status of 401")
        sockets: list[Any] = []
        reconnected = asyncio.Event()

        def through(ws: Any) -> None:
            ws.connect_to_server()
            sockets.append(ws)
            reconnected.set()

        await page.route_web_socket(re.compile(r"/ws(\?|$)"), through)
        await page.goto(fleet.admin_url)
        await password_sign_in(page)
        await expect(page.locator("#connection")).to_have_text("Connected")
        held: list[Any] = []
        snapshot = asyncio.Event()
        holding = True

        async def hold(route: Any) -> None:
            if not holding:
                await route.continue_()
                return
            held.append(route)
            if len(held) >= SNAPSHOT_REQUESTS:
                snapshot.set()

        await page.route(re.compile(r"/api/(?!session)"), hold)
        reconnected.clear()
        await sockets[-1].close(code=1012, reason="server restarting")  # the page reloads
        await reconnected.wait()
        await asyncio.wait_for(snapshot.wait(), 20)
        cookie = next(c for c in await page.context.cookies() if c["name"] == SESSION_COOKIE)
        digest = token_digest(cookie["value"])
        await accounts.store.change_session(digest, seen_at=-(accounts.idle_s + 1))
        holding = False
        for route in held:
            await route.continue_()
        await expect(page.get_by_role("alert")).to_contain_text(re.compile("sign in again", re.I))
        await password_sign_in(page)
        await expect(page.locator("#who")).to_contain_text("Ada Lovelace")
        async with httpx.AsyncClient(base_url=fleet.server.url, timeout=10) as other_tab:
            again = await other_tab.post("/api/session", json={"name": "ada", "password": PASSWORD})
            assert again.status_code == 200, again.text
        await web.open_view(page, "Robots")
        await expect(page.get_by_role("heading", name="Robots")).to_be_visible()
