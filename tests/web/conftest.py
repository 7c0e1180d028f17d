"""Browser tests of the web pages: a real server (+ building simulator + simulated robots) on
127.0.0.1 and Playwright driving Debian's Chromium (/usr/bin/chromium, from system-deps).

Every page fixture fails its test on any JavaScript console error or uncaught exception
(unless the test declared it expected, e.g. the 401 of a wrong token); ``axe_check`` runs the
vendored axe-core and fails on serious or critical violations.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import httpx
import pytest
import yaml

from backend.building.config import BuildingConfig
from backend.settings import Settings, StaticToken
from backend.site.schema import Site
from backend.site.yamlio import load_site_file
from backend.testing import RunningServer, running_server
from building_sim.simulator import BuildingSimulator
from robot_agent.agent import AgentConfig, RobotAgent

pytestmark = pytest.mark.browser

ROOT = Path(__file__).resolve().parents[2]
DEMO_SITE = ROOT / "sites" / "demo_museum.yaml"
SCREENSHOTS = ROOT / "docs" / "screenshots"
CHROMIUM = Path(os.environ.get("GUIDEBOT_CHROMIUM", "/usr/bin/chromium"))
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--headless",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
OPERATOR_TOKEN = "operator-desk-token"
ROBOT_TIME_SCALE = 20.0
BUILDING_TIME_SCALE = 10.0


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    if CHROMIUM.exists():
        return
    skip = pytest.mark.skip(
        reason=f"{CHROMIUM} not found: install Debian's chromium (scripts/system-deps.sh)"
    )
    for item in items:
        if "tests/web/" in str(item.fspath).replace(os.sep, "/"):
            item.add_marker(skip)


@pytest.fixture
async def browser() -> AsyncIterator[Any]:
    from playwright.async_api import async_playwright

    async with async_playwright() as p:
        chromium = await p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        try:
            yield chromium
        finally:
            await chromium.close()


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


@pytest.fixture
async def open_page(browser: Any) -> AsyncIterator[Callable[..., Any]]:
    """``await open_page(url)`` -> PageWatch; each page in its own context (own session)."""
    watches: list[PageWatch] = []

    async def open_(url: str, *, viewport: tuple[int, int] = (1280, 800)) -> PageWatch:
        context = await browser.new_context(viewport={"width": viewport[0], "height": viewport[1]})
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
        watches.append(watch)
        if url:
            await page.goto(url)
        return watch

    yield open_
    problems = [e for w in watches for e in w.unexpected()]
    if problems:
        problems += [f"(HTTP {f})" for w in watches for f in w.failed]
    for w in watches:
        await w.page.context.close()
    assert not problems, "JavaScript errors on the page:\n" + "\n".join(problems)


async def axe_check(page: Any) -> None:
    """Run the vendored axe-core on the page; fail on serious or critical violations."""
    if not await page.evaluate("typeof window.axe !== 'undefined'"):
        await page.add_script_tag(url="/vendor/axe-core/axe.min.js")
    result = await page.evaluate("axe.run(document, {resultTypes: ['violations']})")
    bad = [v for v in result["violations"] if v["impact"] in ("serious", "critical")]
    report = [
        f"{v['id']} ({v['impact']}): {v['help']} — "
        + "; ".join(n["target"][0] if n["target"] else "?" for n in v["nodes"][:5])
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

    @property
    def admin_url(self) -> str:
        return f"{self.server.url}/admin/"

    def http(self, token: str | None = None) -> httpx.AsyncClient:
        token = token or self.server.admin_token
        return httpx.AsyncClient(
            base_url=self.server.url, headers={"Authorization": f"Bearer {token}"}, timeout=10
        )


@pytest.fixture(scope="session")
def demo_site() -> Site:
    return load_site_file(DEMO_SITE)


@contextlib.asynccontextmanager
async def web_fleet(
    tmp_path: Path, demo_site: Site, *, robots: int = 1, **settings: Any
) -> AsyncIterator[WebFleet]:
    """Start the building simulator, the server and ``robots`` robot agents (bare simulated
    bases, no CAN: light) on loopback; the plan images are copied next to the site file."""
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
    async with simulator as building:
        data = demo_site.model_dump(mode="json")
        for module in data["modules"]:
            module["port"] = building.ports[module["id"]]
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
            **settings,
        )
        async with running_server(server_settings) as server, contextlib.AsyncExitStack() as stack:
            agents: dict[str, RobotAgent] = {}
            for robot in demo_site.robots[:robots]:
                agent = RobotAgent(
                    AgentConfig(
                        name=robot.name,
                        server=server.url,
                        token=robot.token,
                        can=None,
                        time_scale=ROBOT_TIME_SCALE,
                        start_node=robot.start_node,
                        speech_engine=None,
                        state_period_s=0.2,
                        site=site_file,
                        auto_answer="yes",
                    )
                )
                await stack.enter_async_context(agent)
                agents[robot.name] = agent
            yield WebFleet(server, building, agents, site_file)


@pytest.fixture
def fleet_factory(
    tmp_path: Path, demo_site: Site
) -> Callable[..., contextlib.AbstractAsyncContextManager[WebFleet]]:
    """``async with fleet_factory(robots=3) as fleet``."""

    def make(**kwargs: Any) -> contextlib.AbstractAsyncContextManager[WebFleet]:
        return web_fleet(tmp_path, demo_site, **kwargs)

    return make


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
        operator_token=OPERATOR_TOKEN,
    )
