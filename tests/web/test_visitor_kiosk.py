"""The visitor panel across a server restart, in kiosk mode, and with a refused request: a small
corridor site (no building), a real server and a simulated robot with its touch screen."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
import yaml
from playwright.async_api import expect

from backend.auth import Role
from backend.settings import Settings, StaticToken
from backend.testing import RunningServer, running_server
from guidebot.testing import wait_until
from robot_agent.agent import RobotAgent
from robot_agent.testing import light_robot

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

PANEL = "panel-kiosk-token"
PHONE = (360, 740)
LONG = 60_000

SITE: dict[str, Any] = {
    "name": "Corridor museum",
    "languages": ["es"],
    "floors": [{"id": "F0"}],
    "nodes": [
        {"id": "home", "floor": "F0", "x": 0, "y": 0},
        {"id": "a", "floor": "F0", "x": 10, "y": 0},
        {"id": "b", "floor": "F0", "x": 20, "y": 0},
    ],
    "edges": [{"a": "home", "b": "a"}, {"a": "a", "b": "b"}],
    "pois": [
        {
            "id": "vase",
            "name": "Vase",
            "node": "a",
            "text": "A vase from a well, two thousand years old.",
        },
        {"id": "coins", "name": "Coins", "node": "b", "text": "Silver coins of three kings."},
    ],
    "tours": [{"id": "walk", "name": "Corridor walk", "points": ["vase", "coins"]}],
    "wait_points": [{"id": "w", "node": "home"}],
    "robots": [{"name": "R1", "token": "robot-R1-kiosk-token", "start_node": "home"}],
}


def settings_for(tmp_path: Path) -> Settings:
    site_file = tmp_path / "site.yaml"
    site_file.write_text(yaml.safe_dump(SITE))
    return Settings(
        db_url=f"sqlite+aiosqlite:///{tmp_path}/guidebot.db",
        site=site_file,
        tokens=[StaticToken(token=PANEL, name="panel-kiosk", role=Role.PANEL)],
    )


@contextlib.asynccontextmanager
async def robot(server: RunningServer, site_file: Path, scale: float) -> AsyncIterator[RobotAgent]:
    agent = light_robot(
        server.url,
        "R1",
        "robot-R1-kiosk-token",
        site=site_file,
        start_node="home",
        time_scale=scale,
    )
    async with agent:
        yield agent


async def test_the_panel_survives_a_server_restart_and_shows_the_true_state(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    settings = settings_for(tmp_path)
    assert settings.site is not None
    first = running_server(settings)
    server = await first.__aenter__()
    port = server.port
    try:
        async with robot(server, settings.site, scale=8.0):
            watch = await open_page(f"{server.url}/visitor/#token={PANEL}", viewport=PHONE)
            # While the server is down the browser reports the refused connections it tried.
            watch.expect_error(r"ERR_CONNECTION_REFUSED")
            page = watch.page
            await (
                page.get_by_role("article", name="Corridor walk")
                .get_by_role("button", name="Take this tour")
                .click()
            )
            state = page.locator(".request-state")
            await expect(state).to_contain_text("R1", timeout=LONG)
            await first.__aexit__(None, None, None)
            first = None
            await expect(page.locator("#connection")).to_contain_text("Connection lost")
            # The robot goes on with the tour alone; the server comes back on the same port.
            async with running_server(settings, port=port) as again:
                await expect(page.locator("#connection")).to_be_hidden(timeout=LONG)
                await expect(state).to_contain_text("The tour has ended", timeout=LONG)
                task = next(iter(again.app.state.task_manager.tasks.values()))
                assert task.state.value == "done"
    finally:
        if first is not None:
            await first.__aexit__(None, None, None)


async def test_kiosk_mode_goes_back_to_the_start_and_keeps_the_visitor_in(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    async with running_server(settings_for(tmp_path)) as server:
        url = f"{server.url}/visitor/#token={PANEL}&kiosk=1&idle=4"
        page = (await open_page(url, viewport=(1280, 800))).page
        await page.get_by_role("button", name="Español").click()
        await expect(page.get_by_role("heading", name="Visitas")).to_be_visible()
        # Nobody touches the kiosk: back to the start screen in the site's default language.
        await expect(page.get_by_role("heading", name="Tours")).to_be_visible(timeout=10_000)
        prevented = await page.evaluate(
            "!document.body.dispatchEvent("
            "new MouseEvent('contextmenu', {cancelable: true, bubbles: true}))"
        )
        assert prevented
        assert await page.locator("a[href]").count() == 0  # no way out of the page
        size = await page.get_by_role("button", name="English").bounding_box()
        assert size is not None and size["height"] >= 64  # large touch targets
        await web.axe_check(page)


async def test_a_refused_request_says_why_on_the_page(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    settings = settings_for(tmp_path)
    assert settings.site is not None
    async with running_server(settings) as server, robot(server, settings.site, scale=8.0):
        watch = await open_page(f"{server.url}/visitor/#token={PANEL}", viewport=PHONE)
        page = watch.page
        watch.expect_error(r"status of 429")
        await expect(page.get_by_role("status").first).to_contain_text("A robot is free")
        # The server's rate limit (HTTP 429, docs/server.md) as the page receives it.
        await page.route(
            "**/api/tasks",
            lambda route: route.fulfill(
                status=429,
                content_type="application/json",
                body='{"detail": "too many task requests: 5 per minute"}',
            ),
        )
        await (
            page.get_by_role("article", name="Corridor walk")
            .get_by_role("button", name="Take this tour")
            .click()
        )
        alert = page.get_by_role("alert")
        await expect(alert).to_contain_text("Too many requests from this panel")
        await expect(alert).to_contain_text("5 per minute")
        await web.axe_check(page)
        # The panel's link drops and comes back (the page then reloads its state over REST):
        # the visitor's error stays until the next tap; a reconnect does not wipe it unread.
        async with page.expect_response("**/api/visitor/requests"):
            server.app.state.hub.clients["panel-kiosk"].request_close(1012, "test: restart")
        await page.wait_for_timeout(500)  # the reload's draw
        await expect(page.locator("#connection")).to_have_attribute("data-status", "open")
        await expect(alert).to_contain_text("Too many requests from this panel", timeout=100)
        # A page opened without its token says how to get one.
        bare = (await open_page(f"{server.url}/visitor/", viewport=PHONE)).page
        await expect(bare.get_by_role("alert")).to_contain_text("has no access key")


async def test_a_language_tap_wins_over_a_slower_reload_started_before_it(
    tmp_path: Path, open_page: Any
) -> None:
    """A hub reconnect reloads the page's data in the language of that moment; a visitor who taps
    another language meanwhile must not be sent back when that older answer arrives last."""
    async with running_server(settings_for(tmp_path)) as server:
        page = (await open_page(f"{server.url}/visitor/#token={PANEL}", viewport=PHONE)).page
        await expect(page.get_by_role("heading", name="Tours")).to_be_visible()
        # The page draws before its hub link is up.
        await wait_until(lambda: "panel-kiosk" in server.app.state.hub.clients)
        english_answered = asyncio.Event()

        async def slow_english(route: Any) -> None:
            await asyncio.sleep(1.0)
            await route.continue_()
            english_answered.set()

        await page.route("**/api/visitor?lang=en", slow_english)
        async with page.expect_request("**/api/visitor?lang=en"):
            server.app.state.hub.clients["panel-kiosk"].request_close(1012, "test: restart")
        await page.get_by_role("button", name="Español").click()
        await expect(page.get_by_role("heading", name="Visitas")).to_be_visible()
        await asyncio.wait_for(english_answered.wait(), 10)
        await page.wait_for_timeout(500)  # the older reload's draw, if it were kept
        await expect(page.get_by_role("heading", name="Visitas")).to_be_visible(timeout=100)
        assert await page.evaluate("document.documentElement.lang") == "es"
