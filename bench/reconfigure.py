"""bench reconfigure: the paper's three hours at a fair, done in the browser (issue 14).

A real server with the demo site, its building simulator and simulated robots; headless
Chromium drives /config as an installer would: adds a node where the welcome stand now is,
joins it with two edges, moves the stand's point of interest onto it, moves the point to a new
place in the ground floor tour (keyboard-free: the up/down buttons) and publishes. Then the
ground tour is requested and the robot's goals are recorded on its on-board bus: the tour is
followed in the new order through the new node.

Last line: {"browser_actions", "browser_seconds", "publish_to_robots_ms",
"tour_followed_new_route", ...}. Goals: under 60 s of browser time, publish to every robot
under 1 s.
"""

from __future__ import annotations

import asyncio
import contextlib
import tempfile
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import click
import httpx
import yaml

from bench.console import CHROMIUM as BENCH_CHROMIUM
from guidebot.benchutil import print_result

ROOT = Path(__file__).resolve().parents[1]
DEMO_SITE = ROOT / "sites" / "demo_museum.yaml"
CHROMIUM = Path(BENCH_CHROMIUM)
CHROMIUM_ARGS = ["--no-sandbox", "--headless", "--disable-gpu", "--no-first-run"]
NEW_NODE = ("stand_new", 27.5, 3.0)
NEW_TOUR = ["mosaics", "amphorae", "sword", "welcome", "loom"]
"""The ground tour after the change: the welcome stand moved east, fourth stop."""
EXPECTED_GOALS = ["ga1", "ga2", "gb1", "stand_new", "gb2"]


class Actions:
    """Counts what the installer does in the browser (clicks, fills, key presses)."""

    def __init__(self, page: Any) -> None:
        self.page = page
        self.count = 0

    async def click(self, locator: Any) -> None:
        self.count += 1
        await locator.click()

    async def click_map(self, x: float, y: float) -> None:
        """Click the plan at site coordinates (metres)."""
        point = await self.page.evaluate(f"guidebotProbe.pointFor({x}, {y})")
        self.count += 1
        await self.page.mouse.click(point["x"], point["y"])

    async def fill(self, locator: Any, text: str) -> None:
        self.count += 1
        await locator.fill(text)
        await locator.press("Enter")  # commits the field (change event)

    async def select(self, locator: Any, value: str) -> None:
        self.count += 1
        await locator.select_option(value)


async def wait_saved(page: Any) -> None:
    """Every edit saved on the server (the page's save queue empty)."""
    await page.evaluate("guidebotProbe.saved()")


async def sign_in(actions: Actions, token: str) -> None:
    page = actions.page
    await actions.fill(page.get_by_label("Admin token"), token)
    await page.get_by_label("Floor", exact=True).wait_for()


async def move_stand(actions: Actions) -> None:
    """The installer's change: new node and edges, the point moved, the tour reordered."""
    from playwright.async_api import expect

    page = actions.page
    node_id, x, y = NEW_NODE
    await actions.click(page.get_by_role("radio", name="Add node"))
    await actions.click_map(x, y)
    await actions.fill(page.get_by_label("id", exact=True), node_id)
    await expect(page.get_by_title(f"node {node_id}")).to_be_visible()
    await actions.click(page.get_by_role("radio", name="Add edge"))
    for a, b in (("corridor_e", node_id), (node_id, "gb1")):
        await actions.click(page.get_by_title(f"node {a}"))
        await actions.click(page.get_by_title(f"node {b}"))
    await actions.click(page.get_by_role("radio", name="Select"))
    await actions.click(page.get_by_role("button", name="Points of interest"))
    await actions.click(page.get_by_role("button", name="Welcome hall (welcome)"))
    await actions.select(page.get_by_label("node", exact=True), node_id)
    await actions.click(page.get_by_role("button", name="Tours"))
    await actions.click(page.get_by_role("button", name="Ground floor tour (ground)"))
    for _ in range(3):
        await actions.click(page.get_by_role("button", name="Move Welcome hall down"))
    await expect(page.locator("ol.tour-points li").nth(3)).to_have_attribute(
        "data-point", "welcome"
    )
    await wait_saved(page)
    await expect(page.locator("#problem-count")).to_have_text("No problems")


async def publish(actions: Actions) -> int:
    """Publish and wait until every connected robot runs the new version; the version."""
    from playwright.async_api import expect

    page = actions.page
    await actions.click(page.get_by_role("button", name="Publish", exact=True))
    await expect(page.locator("#rollout")).to_contain_text("reached all", timeout=20_000)
    status = await page.locator("#draft-status").inner_text()  # "Draft revision R · live version V"
    return int(status.rsplit(" ", 1)[-1])


@dataclass
class Fleet:
    url: str
    admin_token: str
    agents: dict[str, Any]


@contextlib.asynccontextmanager
async def fleet(tmp: Path, robots: int, time_scale: float) -> AsyncIterator[Fleet]:
    """Building simulator, server (demo site, plans copied) and simulated robots, on loopback."""
    from backend.settings import Settings
    from backend.testing import running_server
    from building_sim.simulator import BuildingSimulator
    from guidebot.site.building_config import BuildingConfig
    from guidebot.site.yamlio import load_site_file
    from robot_agent.agent import AgentConfig, RobotAgent

    site = load_site_file(DEMO_SITE)
    sim = BuildingSimulator(
        BuildingConfig(
            modules=site.modules, doors=site.doors, elevators=site.elevators, buttons=site.buttons
        ),
        time_scale=10.0,
        port_zero=True,
        door_hold_s=20.0,
        elevator_hold_s=20.0,
    )
    async with sim as building:
        data = site.model_dump(mode="json")
        for module in data["modules"]:
            module["port"] = building.ports[module["id"]]
        (tmp / "demo_museum").mkdir(exist_ok=True)
        for svg in (DEMO_SITE.parent / "demo_museum").glob("*.svg"):
            (tmp / "demo_museum" / svg.name).write_bytes(svg.read_bytes())
        site_file = tmp / "site.yaml"
        site_file.write_text(yaml.safe_dump(data))
        settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp}/guidebot.db", site=site_file)
        async with running_server(settings) as server, contextlib.AsyncExitStack() as stack:
            agents = {}
            for robot in site.robots[:robots]:
                agents[robot.name] = await stack.enter_async_context(
                    RobotAgent(
                        AgentConfig(
                            name=robot.name,
                            server=server.url,
                            token=robot.token,
                            can=None,
                            time_scale=time_scale,
                            start_node=robot.start_node,
                            speech_engine=None,
                            state_period_s=0.2,
                            site=site_file,
                            auto_answer="yes",
                            gui_port=0,
                        )
                    )
                )
            yield Fleet(server.url, server.admin_token, agents)


async def follow_tour(f: Fleet, tour: str, timeout_s: float) -> list[str]:
    """Request ``tour`` and record the goals the robots reach until the tour ends."""
    goals: list[str] = []
    outcome: list[Any] = []
    ended = asyncio.Event()
    unsubs = []

    def task_ended(message: Any) -> None:
        outcome.append(message.payload)
        ended.set()

    for agent in f.agents.values():
        ep = agent.bus.endpoint(f"bench-{agent.config.name}")
        unsubs.append(ep.subscribe("goal_reached", lambda m: goals.append(m.payload["node"])))
        unsubs.append(ep.subscribe("task_ended", task_ended))
        unsubs.append(ep.subscribe("navigation_failed", lambda m: outcome.append(m.payload)))
    try:
        async with httpx.AsyncClient(
            base_url=f.url, headers={"Authorization": f"Bearer {f.admin_token}"}, timeout=10
        ) as http:
            r = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": tour}})
            r.raise_for_status()
        await asyncio.wait_for(ended.wait(), timeout_s)
    finally:
        for unsub in unsubs:
            unsub()
    goals.extend(f"({o.get('outcome') or o.get('reason')})" for o in outcome)
    return goals


def in_order(seen: list[str], expected: list[str]) -> bool:
    """``expected`` is a subsequence of ``seen``."""
    it = iter(seen)
    return all(any(s == e for s in it) for e in expected)


async def _run(robots: int, time_scale: float, screenshots: Path | None = None) -> dict[str, Any]:
    from playwright.async_api import async_playwright

    with tempfile.TemporaryDirectory(prefix="guidebot-reconfigure-") as tmp:
        async with fleet(Path(tmp), robots, time_scale) as f, async_playwright() as p:
            browser = await p.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
            try:
                page = await browser.new_page(viewport={"width": 1400, "height": 900})
                errors: list[str] = []
                page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
                page.on("pageerror", lambda e: errors.append(str(e)))
                actions = Actions(page)
                start = time.perf_counter()
                try:
                    await page.goto(f"{f.url}/config/")
                    await sign_in(actions, f.admin_token)
                    await move_stand(actions)
                    if screenshots is not None:
                        await page.screenshot(path=str(screenshots / "config-fair-tour.png"))
                    await publish(actions)
                    if screenshots is not None:
                        await page.get_by_role("button", name="Changes in version 2").click()
                        await page.screenshot(path=str(screenshots / "config-fair-published.png"))
                except Exception as exc:
                    raise RuntimeError(f"in the browser: {exc}; page errors: {errors}") from exc
                browser_s = time.perf_counter() - start
            finally:
                await browser.close()
            async with httpx.AsyncClient(
                base_url=f.url, headers={"Authorization": f"Bearer {f.admin_token}"}
            ) as http:
                rollout = (await http.get("/api/site/rollout")).json()
            goals = await follow_tour(f, "ground", timeout_s=180)
    return {
        "browser_actions": actions.count,
        "browser_seconds": round(browser_s, 2),
        "publish_to_robots_ms": rollout["ms"],
        "robots": len(rollout["expected"]),
        "goals": goals,
        "console_errors": errors,
        "tour_followed_new_route": in_order(goals, EXPECTED_GOALS),
    }


@click.command("reconfigure")
@click.option("--robots", default=3, show_default=True, help="Simulated robots connected.")
@click.option("--time-scale", default=20.0, show_default=True, help="Robots' simulated speed-up.")
@click.option(
    "--screenshots",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Write the docs' screenshots of the scenario here (docs/screenshots).",
)
@click.option("--json", "as_json", is_flag=True, help="Only the JSON line.")
def main(robots: int, time_scale: float, screenshots: Path | None, as_json: bool) -> None:
    """Move a stand and change a tour in /config, publish, follow the new tour."""
    result = asyncio.run(_run(robots, time_scale, screenshots))
    if not as_json:
        click.echo(
            f"{result['browser_actions']} browser actions in {result['browser_seconds']} s; "
            f"publish reached {result['robots']} robots in {result['publish_to_robots_ms']} ms; "
            f"new route followed: {result['tour_followed_new_route']}"
        )
    print_result(result)
