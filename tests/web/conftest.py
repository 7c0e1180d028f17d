"""Browser tests of the web pages: a real server (+ building simulator + simulated robots) on
127.0.0.1 and Playwright driving Debian's Chromium (chromium-headless-shell, from system-deps;
``GUIDEBOT_CHROMIUM`` names another: tests/conftest.py).

Every page fixture fails its test on any JavaScript console error or uncaught exception
(unless the test declared it expected, e.g. the 401 of a wrong token); ``axe_check`` runs the
vendored axe-core and fails on serious or critical violations.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import threading
from collections.abc import AsyncIterator, Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any
from urllib.parse import urlsplit

import httpx
import pytest
import pytest_asyncio
import uvicorn
import yaml

from backend.settings import Settings, StaticToken
from backend.testing import RunningServer, running_server
from bench.console import CHROMIUM as BENCH_CHROMIUM
from bench.console import CHROMIUM_ARGS
from building_sim.control import serve_control
from building_sim.simulator import BuildingSimulator
from guidebot.site.building_config import BuildingConfig
from guidebot.site.schema import Site
from guidebot.site.yamlio import load_site_file
from robot_agent.agent import AgentConfig, RobotAgent

ROOT = Path(__file__).resolve().parents[2]
DEMO_SITE = ROOT / "sites" / "demo_museum.yaml"
SCREENSHOTS = ROOT / "docs" / "screenshots"
CHROMIUM = Path(BENCH_CHROMIUM)
OPERATOR_TOKEN = "operator-desk-token"
ROBOT_TIME_SCALE = 20.0
BUILDING_TIME_SCALE = 10.0


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Browser tests run in the event loop of their pytest process (pytest-xdist worker), which
    holds the one Chromium they share (``chromium`` below); without Chromium they are skipped."""
    for item in items:
        if "browser" in getattr(item, "fixturenames", ()):
            # before pytest-asyncio's own mark (auto mode), which names no loop scope
            item.add_marker(pytest.mark.asyncio(loop_scope="session"), append=False)
    if CHROMIUM.exists():
        return
    skip = pytest.mark.skip(
        reason=f"{CHROMIUM} not found: install Debian's chromium (scripts/system-deps.sh)"
    )
    for item in items:
        if item.get_closest_marker("browser") is not None:
            item.add_marker(skip)


@pytest_asyncio.fixture(scope="session", loop_scope="session")
async def chromium() -> AsyncIterator[Any]:
    """One Playwright driver and one Chromium per pytest process, started by the first browser
    test that runs there: starting them took about 0.8 CPU-second per test. Each test still
    gets new browser contexts (``Pages``: no cookies, storage or cache shared) and a fresh
    start of the browser if the last one went away (``browser`` below)."""
    from playwright.async_api import async_playwright

    async with async_playwright() as p:
        launched: list[Any] = []

        async def connected() -> Any:
            if not launched or not launched[-1].is_connected():
                launched.append(
                    await p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
                )
            return launched[-1]

        try:
            yield connected
        finally:
            for chromium in launched:
                if chromium.is_connected():
                    await chromium.close()


@pytest_asyncio.fixture(loop_scope="session")
async def browser(chromium: Any) -> AsyncIterator[Any]:
    """The process's Chromium, for one test, in the event loop the browser tests share: what
    the test's own loop gave it, the shared loop gives it too. Tasks it left running are
    cancelled when it ends, and it has its own default executor (the thread-leak check sees
    the threads stop), as when pytest-asyncio closed a loop of its own after each test."""
    browser = await chromium()
    loop = asyncio.get_running_loop()
    executor = ThreadPoolExecutor(thread_name_prefix="asyncio")
    loop.set_default_executor(executor)
    before = asyncio.all_tasks(loop)
    try:
        yield browser
    finally:
        this = asyncio.current_task()
        left = [t for t in asyncio.all_tasks(loop) if t not in before and t is not this]
        for task in left:
            task.cancel()
        await asyncio.gather(*left, return_exceptions=True)
        await _shut_down(executor)


async def _shut_down(executor: ThreadPoolExecutor) -> None:
    """Wait for the executor's threads to end without blocking the loop (what
    ``loop.shutdown_default_executor`` does for a loop that closes)."""
    loop = asyncio.get_running_loop()
    done = loop.create_future()

    def shut_down() -> None:
        executor.shutdown(wait=True)
        loop.call_soon_threadsafe(done.set_result, None)

    threading.Thread(target=shut_down, name="executor-shutdown", daemon=True).start()
    await done


@dataclass
class PageWatch:
    """A page whose console errors and uncaught exceptions fail the test."""

    page: Any
    errors: list[str] = field(default_factory=list)
    expected: list[re.Pattern[str]] = field(default_factory=list)
    failed: list[str] = field(default_factory=list)
    """HTTP responses >= 400 (named in the failure message: Chromium's console does not)."""

    def expect_error(self, pattern: str) -> None:
        """Console errors matching ``pattern`` are part of the scenario (e.g. a 401)."""
        self.expected.append(re.compile(pattern))

    def unexpected(self) -> list[str]:
        return [e for e in self.errors if not any(p.search(e) for p in self.expected)]

    def expects_its_server_to_go(self) -> bool:
        """The test declared the refused connections of a server going away (a restart)."""
        return any(p.search("net::ERR_CONNECTION_REFUSED") for p in self.expected)


class Pages:
    """The pages a test opened: ``await pages(url)`` opens one (a PageWatch, in its own
    browser context); ``close()`` closes them and keeps their unexpected errors."""

    def __init__(self, browser: Any) -> None:
        self.browser = browser
        self.watches: list[PageWatch] = []
        self.problems: list[str] = []

    async def __call__(self, url: str, *, viewport: tuple[int, int] = (1280, 800)) -> PageWatch:
        context = await self.browser.new_context(
            viewport={"width": viewport[0], "height": viewport[1]}
        )
        page = await context.new_page()
        watch = PageWatch(page)
        page.on(
            "console",
            lambda m: watch.errors.append(f"console: {m.text}") if m.type == "error" else None,
        )
        page.on("pageerror", lambda e: watch.errors.append(f"pageerror: {e}"))
        page.on(
            "response",
            lambda r: watch.failed.append(f"{r.status} {r.url}") if r.status >= 400 else None,
        )
        self.watches.append(watch)
        if url:
            await page.goto(url)
        return watch

    async def close(self) -> None:
        """Close every page (before its server stops: a page whose server went away reports
        connection errors that are not the test's)."""
        for watch in list(self.watches):
            await self._close(watch)

    async def close_on(self, address: str) -> None:
        """Close the pages showing the server at ``address`` (host:port), which is stopping,
        except those that expect it to go."""
        for watch in list(self.watches):
            if watch.page.is_closed() or watch.expects_its_server_to_go():
                continue
            if urlsplit(watch.page.url).netloc == address:
                await self._close(watch)

    async def _close(self, watch: PageWatch) -> None:
        problems = watch.unexpected()
        if problems:
            self.problems += problems + [f"(HTTP {f})" for f in watch.failed]
        self.watches.remove(watch)
        # A route handler still running when its page goes fails its next call; Playwright
        # raised that in the NEXT test's first call on this browser (CI: a later test's
        # new_context failed with this one's "Response has been disposed").
        if not watch.page.is_closed():
            await watch.page.unroute_all(behavior="ignoreErrors")
        await watch.page.context.close()


@pytest_asyncio.fixture(loop_scope="session")
async def open_page(browser: Any, monkeypatch: pytest.MonkeyPatch) -> AsyncIterator[Pages]:
    """``await open_page(url)`` -> PageWatch; any console error fails the test.

    A page closes before the server it shows stops, whichever uvicorn server of the test it is
    (the server's, a robot's touch screen) and whenever it stops: left open, it would log
    its reconnections to a server that is gone (ERR_CONNECTION_REFUSED). A page that expects
    them (it watches its server restart) stays open."""
    pages = Pages(browser)
    shutdown = uvicorn.Server.shutdown

    async def pages_first(server: uvicorn.Server, sockets: Any = None) -> None:
        for listener in server.servers:
            for sock in listener.sockets:
                host, port = sock.getsockname()[:2]
                await pages.close_on(f"{host}:{port}")
        await shutdown(server, sockets)

    monkeypatch.setattr(uvicorn.Server, "shutdown", pages_first)
    yield pages
    await pages.close()
    assert not pages.problems, "JavaScript errors on the page:\n" + "\n".join(pages.problems)


WCAG_TAGS = ["wcag2a", "wcag2aa", "wcag21a", "wcag21aa", "wcag22aa"]
"""axe-core's tags for WCAG 2.2 level A and AA (each WCAG version's new criteria are tagged
with that version: all five make "WCAG 2.2 AA")."""


async def axe_check(page: Any) -> None:
    """Run the vendored axe-core on the page with the WCAG 2.2 AA rules (and axe's best
    practices); fail on any WCAG violation, whatever its impact, and on serious or critical
    best-practice ones. No rule is excluded."""
    if not await page.evaluate("typeof window.axe !== 'undefined'"):
        await page.add_script_tag(url="/vendor/axe-core/axe.min.js")
    tags = [*WCAG_TAGS, "best-practice"]
    result = await page.evaluate(
        "tags => axe.run(document, {runOnly: {type: 'tag', values: tags},"
        " resultTypes: ['violations']})",
        tags,
    )
    bad = [
        v
        for v in result["violations"]
        if set(v["tags"]) & set(WCAG_TAGS) or v["impact"] in ("serious", "critical")
    ]
    report = [
        f"{v['id']} ({v['impact']}): {v['help']} — "
        + "; ".join(n["target"][0] if n["target"] else "?" for n in v["nodes"][:5])
        + f" ({' '.join(v['nodes'][0].get('failureSummary', '').split())})"
        for v in bad
    ]
    assert not bad, "accessibility violations:\n" + "\n".join(report)


async def screenshot(page: Any, name: str) -> None:
    """Write docs/screenshots/<name>.png when GUIDEBOT_SCREENSHOTS=1 (``make screenshots``)."""
    if os.environ.get("GUIDEBOT_SCREENSHOTS") == "1":
        SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        await page.screenshot(path=str(SCREENSHOTS / f"{name}.png"))


@dataclass
class WebFleet:
    """A server with the demo site, its building simulator and simulated robots."""

    server: RunningServer
    building: BuildingSimulator
    agents: dict[str, RobotAgent]
    site_file: Path
    simulator_url: str

    @property
    def admin_url(self) -> str:
        return f"{self.server.url}/admin/"

    def http(self, token: str | None = None) -> httpx.AsyncClient:
        """A staff client; it drops connections idle for 1 s, before the server's keep-alive
        (5 s) does: a request sent on a connection the server was closing failed (ReadError)
        after a test's page work had kept the client idle about 5 s (docs/server.md)."""
        token = token or self.server.admin_token
        return httpx.AsyncClient(
            base_url=self.server.url,
            headers={"Authorization": f"Bearer {token}"},
            timeout=10,
            limits=httpx.Limits(keepalive_expiry=1.0),
        )

    async def kill(self, name: str) -> None:
        """The robot's process dies: its link drops without a goodbye."""
        agent = self.agents.pop(name)
        if agent.hub is not None:  # no last word: a robot that leaves cleanly says so first
            await agent.hub.close(flush=False)
        await agent.__aexit__(None, None, None)


@pytest.fixture(scope="session")
def demo_site() -> Site:
    return load_site_file(DEMO_SITE)


@contextlib.asynccontextmanager
async def web_fleet(
    tmp_path: Path,
    demo_site: Site,
    *,
    robots: int = 1,
    time_scale: float = ROBOT_TIME_SCALE,
    edit: Callable[[dict[str, Any]], None] | None = None,
    screens: bool = False,
    **settings: Any,
) -> AsyncIterator[WebFleet]:
    """Start the building simulator (with its control API), the server and ``robots`` robot
    agents (bare simulated bases, no CAN: light) on loopback; ``edit`` may change the site
    document first. The plan images are copied next to the site file. Without ``screens`` a
    robot has no touch screen, so nobody answers "continue the tour?" and a tour ends after its
    first stop (the visitor left); with them a simulated visitor answers yes.

    The robots report their state twice a second (a real robot's default is once): at five a
    second the server's broadcast and every open page's redraws cost 10 % more CPU in the
    browser tests, for nothing they check."""
    config = BuildingConfig(
        modules=demo_site.modules,
        doors=demo_site.doors,
        elevators=demo_site.elevators,
        buttons=demo_site.buttons,
    )
    simulator = BuildingSimulator(
        config,
        time_scale=BUILDING_TIME_SCALE,
        port_zero=True,
        door_hold_s=2.0 * BUILDING_TIME_SCALE,
        elevator_hold_s=2.0 * BUILDING_TIME_SCALE,
    )
    async with simulator as building, serve_control(building) as control_url:
        data = demo_site.model_dump(mode="json")
        for module in data["modules"]:
            module["port"] = building.ports[module["id"]]
        if edit is not None:
            edit(data)
        start_nodes = {r["name"]: r.get("start_node") for r in data["robots"]}
        plans = tmp_path / "demo_museum"
        plans.mkdir(exist_ok=True)
        for svg in (DEMO_SITE.parent / "demo_museum").glob("*.svg"):
            (plans / svg.name).write_bytes(svg.read_bytes())
        site_file = tmp_path / "site.yaml"
        site_file.write_text(yaml.safe_dump(data))
        server_settings = Settings(
            db_url=f"sqlite+aiosqlite:///{tmp_path}/guidebot.db",
            site=site_file,
            tokens=[StaticToken(token=OPERATOR_TOKEN, name="desk", role="operator")],
            building_sim_url=control_url,
            **settings,
        )
        async with running_server(server_settings) as server:
            fleet = WebFleet(server, building, {}, site_file, control_url)
            try:
                for robot in demo_site.robots[:robots]:
                    agent = RobotAgent(
                        AgentConfig(
                            name=robot.name,
                            server=server.url,
                            token=robot.token,
                            can=None,
                            time_scale=time_scale,
                            start_node=start_nodes.get(robot.name, robot.start_node),
                            speech_engine=None,
                            state_period_s=0.5,
                            site=site_file,
                            auto_answer="yes",
                            gui_port=0 if screens else None,
                        )
                    )
                    await agent.__aenter__()
                    fleet.agents[robot.name] = agent
                yield fleet
            finally:
                for name in list(fleet.agents):
                    await fleet.kill(name)


@pytest.fixture
def fleet_factory(
    tmp_path: Path, demo_site: Site, open_page: Pages
) -> Callable[..., contextlib.AbstractAsyncContextManager[WebFleet]]:
    """``async with fleet_factory(robots=3) as fleet``; the test's pages close before the
    fleet stops."""

    @contextlib.asynccontextmanager
    async def make(**kwargs: Any) -> AsyncIterator[WebFleet]:
        async with web_fleet(tmp_path, demo_site, **kwargs) as fleet:
            try:
                yield fleet
            finally:
                await open_page.close()

    return make


async def open_view(page: Any, name: str) -> None:
    """Click a view's tab."""
    await page.locator("#tabs").get_by_role("button", name=name).click()


async def sign_in(watch: PageWatch, token: str) -> None:
    """Sign in on the console's form and wait for the map."""
    page = watch.page
    await page.get_by_label("Staff token").fill(token)
    await page.get_by_role("button", name="Sign in").click()
    await page.get_by_label("Floor", exact=True).wait_for()


@pytest.fixture
def web() -> SimpleNamespace:
    """The helpers, as a fixture: test modules here do not import each other."""
    return SimpleNamespace(
        axe_check=axe_check,
        screenshot=screenshot,
        sign_in=sign_in,
        open_view=open_view,
        operator_token=OPERATOR_TOKEN,
    )
