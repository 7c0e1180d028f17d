"""The visitor panel across a server restart, in kiosk mode, and with a refused request: a small
corridor site (no building), a real server and a simulated robot with its touch screen."""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
from collections.abc import AsyncIterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import httpx
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
    async with (
        running_server(settings) as server,
        robot(server, settings.site, scale=8.0),
    ):
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


async def test_a_visitor_asks_for_one_exhibit_and_a_robot_takes_them_there(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    settings = settings_for(tmp_path)
    assert settings.site is not None
    async with (
        running_server(settings) as server,
        robot(server, settings.site, scale=8.0),
    ):
        page = (await open_page(f"{server.url}/visitor/#token={PANEL}", viewport=PHONE)).page
        await expect(page.get_by_role("status").first).to_contain_text("A robot is free")
        coins = page.get_by_role("article", name="Coins")
        await coins.get_by_role("button", name="Take me there").click()
        state = page.locator(".request-state")
        await expect(state).to_contain_text("R1 is going to Coins", timeout=LONG)
        await web.axe_check(page)
        await expect(state).to_contain_text("R1 has shown you Coins", timeout=LONG)
        await expect(page.get_by_role("button", name="Ask for something else")).to_be_visible()
        tasks = server.app.state.task_manager.tasks.values()
        done = [t for t in tasks if t.kind == "go_to_poi"]
        assert len(done) == 1 and done[0].params["poi"] == "coins"
        assert done[0].state.value == "done" and done[0].robot == "R1"


async def test_news_of_a_request_that_comes_before_its_answer_is_not_lost(
    tmp_path: Path, open_page: Any
) -> None:
    """A point visit a free robot starts at once: the hub may tell the page the task runs
    before the page has the answer to its own request. The page shows it running, not
    "assigned" until it ends (found by tests/web/test_busy_truth.py)."""
    settings = settings_for(tmp_path)
    assert settings.site is not None
    async with (
        running_server(settings) as server,
        robot(server, settings.site, scale=0.5),
    ):
        page = (await open_page(f"{server.url}/visitor/#token={PANEL}", viewport=PHONE)).page
        frames: list[str] = []
        told = asyncio.Event()

        def on_socket(socket: Any) -> None:
            def on_frame(payload: str | bytes) -> None:
                text = payload if isinstance(payload, str) else payload.decode()
                frames.append(text)
                if '"running"' in text and "task_event" in text:
                    told.set()

            socket.on("framereceived", on_frame)

        page.on("websocket", on_socket)
        await expect(page.get_by_role("status").first).to_contain_text("A robot is free")

        async def answer_after_the_news(route: Any) -> None:
            response = await route.fetch()
            await asyncio.wait_for(told.wait(), LONG / 1000)
            await route.fulfill(response=response)

        await page.route("**/api/tasks", answer_after_the_news)
        coins = page.get_by_role("article", name="Coins")
        await coins.get_by_role("button", name="Take me there").click()
        await expect(page.locator(".request-state")).to_have_class(re.compile(r"\brunning\b"))


def task_events(payload: str | bytes) -> list[dict[str, Any]]:
    """The task_event payloads of one hub frame (one message or a batch)."""
    data = json.loads(payload)
    messages = data if isinstance(data, list) else [data]
    return [m["payload"] for m in messages if m.get("type") == "task_event"]


async def test_a_request_back_in_line_before_its_answer_comes_shows_in_line(
    tmp_path: Path, open_page: Any
) -> None:
    """The answer to a request was read when a robot had it (assigned or running); the task
    went back to the queue (a visit waiting for trouble to lift, staff taking it off the
    robot) and the hub told the page before that answer came. The page shows it in line, not
    "assigned" for ever: newest news wins, backwards too (test_busy_truth saw a phone stay
    "assigned to R1" for 15 reads while the API said "queued, number 3")."""
    settings = settings_for(tmp_path)
    assert settings.site is not None
    async with (
        running_server(settings) as server,
        robot(server, settings.site, scale=0.5),
        httpx.AsyncClient(
            base_url=server.url, headers={"Authorization": f"Bearer {server.admin_token}"}
        ) as staff,
    ):
        page = (await open_page(f"{server.url}/visitor/#token={PANEL}", viewport=PHONE)).page
        queued: dict[str, asyncio.Event] = {}

        def on_socket(socket: Any) -> None:
            def on_frame(payload: str | bytes) -> None:
                for event in task_events(payload):
                    if event["state"] == "queued" and event.get("robot") is None:
                        queued.setdefault(event["task_id"], asyncio.Event()).set()

            socket.on("framereceived", on_frame)

        page.on("websocket", on_socket)
        await expect(page.get_by_role("status").first).to_contain_text("A robot is free")

        async def answer_after_the_requeue(route: Any) -> None:
            response = await route.fetch()
            answer = await response.json()
            assert answer["state"] in ("assigned", "running") and answer["robot"] == "R1", answer
            back = await staff.post(f"/api/tasks/{answer['id']}/reassign", json={})
            assert back.status_code == 200, back.text
            told = queued.setdefault(answer["id"], asyncio.Event())
            await asyncio.wait_for(told.wait(), LONG / 1000)
            await route.fulfill(response=response)

        await page.route("**/api/tasks", answer_after_the_requeue)
        coins = page.get_by_role("article", name="Coins")
        await coins.get_by_role("button", name="Take me there").click()
        state = page.locator(".request-state")
        await expect(state).to_have_class(re.compile(r"\bqueued\b"))
        await expect(state).to_contain_text("You are number 1 in line")
        await expect(page.locator(".robot-name")).to_have_count(0)


async def test_a_refused_token_is_said_on_the_page_without_an_error(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    """A wrong or rotated panel token: the page says so instead of "Loading…" for ever."""
    async with running_server(settings_for(tmp_path)) as server:
        watch = await open_page(f"{server.url}/visitor/#token=an-old-panel-token", viewport=PHONE)
        watch.expect_error(r"status of 401")
        page = watch.page
        await expect(page.get_by_role("alert")).to_contain_text(
            "The access key of this panel was not accepted"
        )
        await expect(page.get_by_text("Loading…")).to_have_count(0)
        await expect(page.locator("#app")).to_have_attribute("aria-busy", "false")
        await web.axe_check(page)


async def test_each_device_under_one_panel_token_sees_and_cancels_only_its_own(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    """Phones sharing the QR code's token are told apart by the device id each keeps; the
    panel's rate limit stays one for all of them."""
    settings = settings_for(tmp_path)
    assert settings.site is not None
    async with (
        running_server(settings) as server,
        robot(server, settings.site, scale=0.5),
    ):
        async with httpx.AsyncClient(
            base_url=server.url, headers={"Authorization": f"Bearer {server.admin_token}"}
        ) as staff:  # the robot is busy: the visitors' requests wait in line
            r = await staff.post(
                "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": "coins"}}
            )
            assert r.status_code == 201, r.text
        url = f"{server.url}/visitor/#token={PANEL}"
        first = (await open_page(url, viewport=PHONE)).page
        second = (await open_page(url, viewport=PHONE)).page
        await expect(first.get_by_role("status").first).to_contain_text("Every robot is busy")
        await (
            first.get_by_role("article", name="Corridor walk")
            .get_by_role("button", name="Take this tour")
            .click()
        )
        await expect(first.locator(".request-state")).to_contain_text("number 1 in line")
        await second.reload()
        await expect(second.get_by_role("heading", name="Tours")).to_be_visible()
        await expect(second.get_by_role("button", name="Your request: ")).to_have_count(0)
        await (
            second.get_by_role("article", name="Vase")
            .get_by_role("button", name="Take me there")
            .click()
        )
        await expect(second.locator(".request-state")).to_contain_text("number 2 in line")
        await second.get_by_role("button", name="Back to the start").click()
        await expect(second.get_by_role("button", name="Your request: ")).to_have_text(
            ["Your request: Vase"]
        )
        await first.reload()
        await expect(first.get_by_role("button", name="Your request: ")).to_have_text(
            ["Your request: Corridor walk"]
        )
        await web.axe_check(second)
        # The server enforces it: the second device can neither read nor cancel the first's.
        device = await second.evaluate("localStorage.getItem('guidebot.visitor.device')")
        assert device != await first.evaluate("localStorage.getItem('guidebot.visitor.device')")
        walk = next(t for t in server.app.state.task_manager.tasks.values() if t.kind == "tour")
        assert walk.requester.startswith("panel-kiosk/")
        headers = {"Authorization": f"Bearer {PANEL}", "X-Guidebot-Device": device}
        async with httpx.AsyncClient(base_url=server.url, headers=headers) as phone:
            assert (await phone.get(f"/api/tasks/{walk.id}")).status_code == 404
            assert (await phone.post(f"/api/tasks/{walk.id}/cancel")).status_code == 404
            mine = (await phone.get("/api/visitor/requests")).json()
            assert [t["params"]["poi"] for t in mine] == ["vase"]
            bad = await phone.get("/api/visitor/requests", headers={"X-Guidebot-Device": "x"})
            assert bad.status_code == 422
        assert walk.state.value == "queued"
        # One rate limit for the panel, whatever device ids its callers send (a burst of 5:
        # two requests made above, so a fresh id each time is refused by the sixth at most).
        async with httpx.AsyncClient(base_url=server.url) as anyone:
            codes = []
            for n in range(6):
                r = await anyone.post(
                    "/api/tasks",
                    json={"kind": "go_to_poi", "params": {"poi": "vase"}},
                    headers={
                        "Authorization": f"Bearer {PANEL}",
                        "X-Guidebot-Device": f"fresh-device-{n:04d}-xyz",
                    },
                )
                codes.append(r.status_code)
            assert 429 in codes and codes.index(429) <= 4, codes


async def test_a_kiosk_forgets_the_last_visitors_requests_when_it_goes_back_to_the_start(
    tmp_path: Path, open_page: Any
) -> None:
    settings = settings_for(tmp_path)
    assert settings.site is not None
    async with (
        running_server(settings) as server,
        robot(server, settings.site, scale=0.5),
    ):
        url = f"{server.url}/visitor/#token={PANEL}&kiosk=1&idle=3"
        page = (await open_page(url, viewport=(1280, 800))).page
        await (
            page.get_by_role("article", name="Corridor walk")
            .get_by_role("button", name="Take this tour")
            .click()
        )
        await expect(page.locator(".request-state")).to_contain_text("R1", timeout=LONG)
        await page.get_by_role("button", name="Back to the start").click()
        await expect(page.get_by_role("button", name="Your request: ")).to_have_count(1)
        # Nobody touches the kiosk: the next visitor does not see (nor cancel) that request.
        await expect(page.get_by_role("button", name="Your request: ")).to_have_count(
            0, timeout=10_000
        )
        walk = next(t for t in server.app.state.task_manager.tasks.values() if t.kind == "tour")
        assert not walk.final  # it stays with the server


async def test_a_visitor_in_line_sees_the_line_move(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    """Place in line and wait follow the server while queued (no tap, no reload)."""
    settings = settings_for(tmp_path)
    assert settings.site is not None
    async with (
        running_server(settings) as server,
        robot(server, settings.site, scale=0.5),
    ):
        manager = server.app.state.task_manager
        async with httpx.AsyncClient(
            base_url=server.url, headers={"Authorization": f"Bearer {server.admin_token}"}
        ) as staff:
            ids = []
            for poi in ("coins", "vase"):
                r = await staff.post(
                    "/api/tasks", json={"kind": "go_to_poi", "params": {"poi": poi}}
                )
                assert r.status_code == 201, r.text
                ids.append(r.json()["id"])
            page = (await open_page(f"{server.url}/visitor/#token={PANEL}", viewport=PHONE)).page
            await (
                page.get_by_role("article", name="Corridor walk")
                .get_by_role("button", name="Take this tour")
                .click()
            )
            state = page.locator(".request-state")
            await expect(state).to_contain_text("You are number 2 in line")
            walk = next(t for t in manager.tasks.values() if t.kind == "tour")
            before = (await staff.get(f"/api/tasks/{walk.id}")).json()["eta_s"]
            # The task ahead of it leaves the line: the visitor's page follows by itself.
            r = await staff.post(f"/api/tasks/{ids[1]}/cancel", json={"reason": "not needed"})
            assert r.status_code == 200, r.text
            await expect(state).to_contain_text("You are number 1 in line")
            now = (await staff.get(f"/api/tasks/{walk.id}")).json()
            assert now["queue_position"] == 1 and now["eta_s"] < before
            await web.axe_check(page)


async def test_a_tour_cancelled_by_staff_is_said_to_its_visitor(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    settings = settings_for(tmp_path)
    assert settings.site is not None
    async with (
        running_server(settings) as server,
        robot(server, settings.site, scale=0.5),
    ):
        page = (await open_page(f"{server.url}/visitor/#token={PANEL}", viewport=PHONE)).page
        await (
            page.get_by_role("article", name="Corridor walk")
            .get_by_role("button", name="Take this tour")
            .click()
        )
        state = page.locator(".request-state")
        await expect(state).to_contain_text("Robot R1 is coming for you", timeout=LONG)
        walk = next(t for t in server.app.state.task_manager.tasks.values() if t.kind == "tour")
        async with httpx.AsyncClient(
            base_url=server.url, headers={"Authorization": f"Bearer {server.admin_token}"}
        ) as staff:
            r = await staff.post(
                f"/api/tasks/{walk.id}/cancel", json={"reason": "the museum closes early"}
            )
            assert r.status_code == 200, r.text
            assert r.json()["cancelled_by"] == "staff"
        await expect(state).to_contain_text("Your tour was cancelled by staff")
        await web.axe_check(page)
        # Read again over REST (a reconnect, e.g. a server restart) it still says so.
        async with page.expect_response(f"**/api/tasks/{walk.id}"):
            server.app.state.hub.clients["panel-kiosk"].request_close(1012, "test: restart")
        await expect(state).to_contain_text("Your tour was cancelled by staff")
        # The visitor's own cancel is said as such (not "by staff").
        await page.get_by_role("button", name="Ask for another tour").click()
        await (
            page.get_by_role("article", name="Corridor walk")
            .get_by_role("button", name="Take this tour")
            .click()
        )
        await page.get_by_role("button", name="Cancel my request").click()
        await page.get_by_role("button", name="Yes, cancel it").click()
        await expect(state).to_have_text("Your request was cancelled.")
