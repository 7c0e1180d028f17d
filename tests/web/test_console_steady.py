"""The console's map holds still under the operator's pointer and says where every robot is, in
a real browser against a real server: the status bars (connection lost, alerts, a refresh that
failed) never move the map; robots standing together keep their spots when another one comes;
a robot is selected from the keyboard (Enter, Space); a lost robot stays where it was last
seen, marked lost, on the map and in the Fleet view.

The robots here are the site's robots' hub links driven by the test (their robot_state sent at
the poses the test chooses), so where each marker must be is known exactly."""

from __future__ import annotations

import asyncio
import contextlib
import re
import time
from collections.abc import AsyncIterator
from types import SimpleNamespace
from typing import Any

import orjson
import pytest
import websockets
from playwright.async_api import expect

from guidebot.testing import wait_until

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

STATE_EVERY_S = 1.0
"""How often a driven robot repeats its state (the server counts one silent for 10 s as lost)."""


def quiet_site(data: dict[str, Any]) -> None:
    """No wait point: the Task Manager sends no idle robot anywhere."""
    data["wait_points"] = []


class DrivenRobot:
    """A robot's hub link whose robot_state the test sets; ``drop()`` cuts the link without a
    goodbye (a robot whose process died)."""

    def __init__(self, name: str, link: Any) -> None:
        self.name = name
        self.link = link
        self.payload: dict[str, Any] | None = None
        self.seq = 0
        self.repeat: asyncio.Task[None] | None = None

    async def at(self, node: dict[str, Any]) -> None:
        """Stand at a site node (its pose), idle."""
        self.payload = {
            "robot": self.name, "x": node["x"], "y": node["y"], "theta": 0.0,
            "floor": node["floor"], "node": node["id"], "battery": 0.9, "mode": "idle",
        }  # fmt: skip
        await self.send()
        if self.repeat is None:
            self.repeat = asyncio.create_task(self.keep_sending())

    async def send(self) -> None:
        assert self.payload is not None
        self.seq += 1
        message = {
            "type": "robot_state",
            "id": f"{self.name}-{self.seq}",
            "timestamp": time.time(),
            "payload": {**self.payload, "seq": self.seq},
        }
        await self.link.send(orjson.dumps(message).decode())

    async def keep_sending(self) -> None:
        while True:
            await asyncio.sleep(STATE_EVERY_S)
            await self.send()

    async def drop(self) -> None:
        if self.repeat is not None:
            self.repeat.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self.repeat
            self.repeat = None
        self.link.transport.abort()  # no close frame: the link just goes


@contextlib.asynccontextmanager
async def driven(fleet: Any, demo_site: Any, *names: str) -> AsyncIterator[dict[str, DrivenRobot]]:
    tokens = {r.name: r.token for r in demo_site.robots}
    robots: dict[str, DrivenRobot] = {}
    async with contextlib.AsyncExitStack() as stack:
        for name in names:
            link = await stack.enter_async_context(
                websockets.connect(f"{fleet.server.ws_url}?token={tokens[name]}", proxy=None)
            )
            await link.recv()  # welcome
            robots[name] = DrivenRobot(name, link)
        try:
            yield robots
        finally:
            for robot in robots.values():
                if robot.repeat is not None:
                    robot.repeat.cancel()
                    with contextlib.suppress(asyncio.CancelledError):
                        await robot.repeat


def node(demo_site: Any, node_id: str) -> dict[str, Any]:
    n = next(n for n in demo_site.nodes if n.id == node_id)
    return {"id": n.id, "x": n.x, "y": n.y, "floor": n.floor}


SETTLED = """sel => {
  const el = document.querySelector(sel);
  const now = el && !document.querySelector('.leaflet-zoom-anim')
    ? JSON.stringify(el.getBoundingClientRect()) : null;
  const same = now !== null && now === window.settledRect;
  window.settledRect = now;
  return same;
}"""
"""True once the element is drawn at the same place two frames in a row (the map's fit to its
floor is animated)."""


async def box(locator: Any) -> tuple[float, float, float, float]:
    """Where the element is drawn, once the map holds still."""
    page = locator.page
    selector = await locator.evaluate(
        "el => { el.dataset.measured = '1'; return '[data-measured]'; }"
    )
    await page.wait_for_function(SETTLED, arg=selector, polling="raf")
    await locator.evaluate("el => delete el.dataset.measured")
    b = await locator.bounding_box()
    assert b is not None
    return (round(b["x"], 1), round(b["y"], 1), round(b["width"], 1), round(b["height"], 1))


def marker(page: Any, name: str) -> Any:
    return page.locator(f'#map .robot-marker[aria-label^="robot {name}"]')


async def test_status_bars_never_move_the_map_under_the_pointer(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Any
) -> None:
    """An alert, a refresh that failed and the live connection lost each show a bar: the map
    and the robot on it stay where they were, and a click at the robot's place selects it (the
    alert bar pushed the map down: the click landed beside the robot)."""
    async with fleet_factory(robots=0, edit=quiet_site) as fleet:
        watch = await open_page("")
        page = watch.page
        cut = asyncio.Event()

        async def through(ws: Any) -> None:
            if cut.is_set():
                await ws.close(code=1012, reason="server restarting")
            else:
                ws.connect_to_server()
                sockets.append(ws)

        sockets: list[Any] = []
        await page.route_web_socket(re.compile(r"/ws(\?|$)"), through)
        await page.goto(fleet.admin_url)
        await web.sign_in(watch, fleet.server.admin_token)
        async with driven(fleet, demo_site, "R1") as robots:
            await robots["R1"].at(node(demo_site, "hall"))
            r1 = marker(page, "R1")
            await expect(r1).to_be_visible(timeout=20_000)
            the_map = page.locator("#map")
            before = (await box(the_map), await box(r1))

            async def still() -> None:
                assert (await box(the_map), await box(r1)) == before
                x, y, w, h = before[1]
                await page.mouse.click(x + w / 2, y + h / 2)
                await expect(page.locator("#details h3")).to_have_text("Robot R1")
                await page.locator("#map path.map-door").first.click()  # select something else
                await expect(page.locator("#details h3")).not_to_have_text("Robot R1")

            fleet.server.app.state.alerts.raise_("task_failed", "t1", "a tour failed", "warning")
            await expect(page.locator("#alert-bar")).to_contain_text("1 open alert")
            await still()
            watch.expect_error(r"status of 500")
            await page.route("**/api/locks", lambda route: route.fulfill(status=500, body="{}"))
            await sockets[-1].close(code=1012, reason="server restarting")
            await expect(page.locator("#page-error")).to_contain_text("could not refresh")
            await still()
            cut.set()
            await sockets[-1].close(code=1012, reason="server restarting")
            lost = page.get_by_role("status").filter(has_text="Connection lost, reconnecting")
            await expect(lost).to_be_visible()
            await still()
            await web.axe_check(page)
            await web.screenshot(page, "console-status-line")


async def test_robots_standing_together_keep_their_spots_when_another_comes(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Any
) -> None:
    """R1 and R2 wait at the hall; R3 comes: R1 and R2 stay where they are drawn (they moved
    round the place to make room, so a click aimed at one landed on another)."""
    async with fleet_factory(robots=0, edit=quiet_site) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        hall = node(demo_site, "hall")
        async with driven(fleet, demo_site, "R1", "R2", "R3") as robots:
            await robots["R1"].at(hall)
            await expect(marker(page, "R1")).to_be_visible(timeout=20_000)
            alone = await box(marker(page, "R1"))
            await robots["R2"].at(hall)
            await expect(marker(page, "R2")).to_be_visible()
            two = {n: await box(marker(page, n)) for n in ("R1", "R2")}
            assert two["R1"] == alone  # the first one there keeps the place
            assert abs(two["R1"][0] - two["R2"][0]) + abs(two["R1"][1] - two["R2"][1]) >= 30
            await robots["R3"].at(hall)
            await expect(marker(page, "R3")).to_be_visible()
            three = {n: await box(marker(page, n)) for n in ("R1", "R2", "R3")}
            assert {n: three[n] for n in two} == two
            spots = {(round(b[0]), round(b[1])) for b in three.values()}
            assert len(spots) == 3, three
            # R2 leaves (upstairs): R1 and R3 stay where they are.
            await robots["R2"].at(node(demo_site, "landing"))
            await expect(marker(page, "R2")).to_be_hidden()
            assert await box(marker(page, "R1")) == three["R1"]
            assert await box(marker(page, "R3")) == three["R3"]


LABEL_SEEN = """el => {
    const r = el.querySelector('.robot-label').getBoundingClientRect();
    const top = document.elementFromPoint(r.x + r.width / 2, r.y + r.height / 2);
    return el.contains(top);
}"""
"""Whether a robot's label is the topmost thing at its own centre (no other marker over it)."""


async def test_two_robots_a_little_apart_are_both_seen_and_labelled(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Any
) -> None:
    """Two tours at one exhibit, R1 and R2 0.6 m apart: at the console's zoom their markers
    were drawn one over the other and R1's label hidden under R2 (the busy demo). Closer than a
    marker and its label on the screen, they are drawn apart, R1 (there first) at its pose."""
    async with fleet_factory(robots=0, edit=quiet_site) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        hall = node(demo_site, "hall")
        async with driven(fleet, demo_site, "R1", "R2") as robots:
            await robots["R1"].at(hall)
            await expect(marker(page, "R1")).to_be_visible(timeout=20_000)
            alone = await box(marker(page, "R1"))
            await robots["R2"].at({**hall, "y": hall["y"] - 0.6})
            await expect(marker(page, "R2")).to_be_visible()
            two = {n: await box(marker(page, n)) for n in ("R1", "R2")}
            assert two["R1"] == alone  # the first one there stays at its pose
            assert abs(two["R1"][0] - two["R2"][0]) + abs(two["R1"][1] - two["R2"][1]) >= 30
            for name in ("R1", "R2"):
                assert await marker(page, name).evaluate(LABEL_SEEN), f"{name}'s label is hidden"
            # R2 drives off along the corridor: drawn where it is again, R1 still at its pose.
            await robots["R2"].at(node(demo_site, "door_hall"))
            door = await box(marker(page, "R2"))
            assert await box(marker(page, "R1")) == alone
            assert door[0] - alone[0] > 30


async def test_enter_and_space_on_a_focused_robot_select_it(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Any
) -> None:
    async with fleet_factory(robots=0, edit=quiet_site) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        async with driven(fleet, demo_site, "R1", "R2") as robots:
            await robots["R1"].at(node(demo_site, "hall"))
            await robots["R2"].at(node(demo_site, "entrance"))
            details = page.locator("#details h3")
            for name, key in (("R1", "Enter"), ("R2", " "), ("R1", " "), ("R2", "Enter")):
                await expect(marker(page, name)).to_be_visible(timeout=20_000)
                await marker(page, name).focus()
                await page.keyboard.press("Space" if key == " " else key)
                await expect(details).to_have_text(f"Robot {name}")
                await expect(marker(page, name)).to_be_focused()
            assert await page.evaluate("() => window.scrollY") == 0  # Space did not scroll


async def test_a_lost_robot_stays_where_it_was_last_seen_marked_lost(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Any
) -> None:
    """R1's link drops while the console watches, R2's dropped before it was opened: both are
    on the map where they were last seen, grey and labelled lost, as in the Fleet view and the
    Robots view; R1 back online is drawn live again."""
    async with fleet_factory(robots=0, edit=quiet_site) as fleet:
        async with driven(fleet, demo_site, "R1", "R2") as robots:
            await robots["R2"].at(node(demo_site, "entrance"))
            known = fleet.server.app.state.task_manager.robots
            await wait_until(lambda: known["R2"].node == "entrance")
            await robots["R2"].drop()
            await wait_until(lambda: not known["R2"].online)
            watch = await open_page(fleet.admin_url)
            page = watch.page
            await web.sign_in(watch, web.operator_token)
            await robots["R1"].at(node(demo_site, "hall"))
            r1, r2 = marker(page, "R1"), marker(page, "R2")
            await expect(r1).to_be_visible(timeout=20_000)
            await expect(r1).to_have_attribute("aria-label", "robot R1")
            await expect(r2).to_have_attribute("aria-label", "robot R2 (lost)")
            where = await box(r1)
            await robots["R1"].drop()
            await expect(r1).to_have_attribute("aria-label", "robot R1 (lost)", timeout=20_000)
            await expect(r1.locator(".robot-body")).to_have_class(re.compile(r"\blost\b"))
            await expect(r1).to_contain_text("R1 (lost)")
            assert await box(r1) == where
            await r1.focus()
            await page.keyboard.press("Enter")
            details = page.locator("#details")
            await expect(details).to_contain_text("Connection")
            connection = details.locator("dt", has_text="Connection")
            await expect(connection.locator("xpath=following-sibling::dd[1]")).to_have_text("lost")
            await expect(details).to_contain_text("Last seen")
            await expect(details).to_contain_text("Welcome hall")
            await web.axe_check(page)
            await web.open_view(page, "Fleet")
            ground = page.locator('[data-floor="F0"]')
            for name in ("R1", "R2"):
                robot = ground.locator(f'[data-robot="{name}"]')
                await expect(robot).to_have_attribute("data-link", "lost")
                await expect(robot).to_contain_text(f"{name} (lost)")
            await web.open_view(page, "Robots")
            await expect(page.locator("#robot-R1")).to_contain_text("lost")
