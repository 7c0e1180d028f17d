"""The console across the end of a sign-in, in a real browser against a real server: a person
thrown out (their account disabled: the hub closes with "session ended") signs in again on the
same page and gets one working console, not a broken second one beside a stale first."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

PASSWORD = "Tall-ships sail at dawn 7"

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
