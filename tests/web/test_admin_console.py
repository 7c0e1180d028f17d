"""The staff console's views in a real browser against a real server, the building simulator
and simulated robots: roles, a tour from request to end, a robot lost mid-tour with its lock,
the building, alerts across a restart."""

from __future__ import annotations

import asyncio
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from backend.settings import Settings
from backend.testing import running_server
from guidebot.messages import Message

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]

VIEWS = [
    ("Map", "map"),
    ("Robots", "robots"),
    ("Tasks", "tasks"),
    ("Fleet", "fleet"),
    ("Locks", "locks"),
    ("Building", "building"),
    ("Modes", "modes"),
    ("RoboGraph monitor", "monitor"),
    ("Alerts", "alerts"),
    ("Event log", "events"),
    ("Reports", "reports"),
    ("Notifications", "notifications"),
    ("Bookings", "bookings"),
]


ON_PLAN = """() => {
    const plan = document.querySelector('#map img.leaflet-image-layer').getBoundingClientRect();
    const robot = document.querySelector('#map [aria-label="robot R1"]').getBoundingClientRect();
    return [(robot.x + robot.width / 2 - plan.x) / plan.width,
            (robot.y + robot.height / 2 - plan.y) / plan.height];
}"""
"""Where robot R1 is drawn on the plan shown, as fractions of the plan's width and height
(whatever the zoom and the pan)."""


def short_tours(data: dict[str, Any]) -> None:
    data["tours"] += [
        {"id": "short", "name": "Short tour", "points": ["welcome", "mosaics"]},
        {"id": "east", "name": "East wing", "points": ["sword"]},
    ]


async def test_every_view_and_what_each_role_may_do(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1) as fleet:
        admin = await open_page(fleet.admin_url)
        await web.sign_in(admin, fleet.server.admin_token)
        page = admin.page
        await expect(page.get_by_role("button", name="robot R1")).to_be_visible(timeout=20_000)
        await expect(page.locator("#server-status")).to_have_text("Server ok")  # one process
        for label, name in VIEWS:
            await web.open_view(page, label)
            if name == "monitor":  # the idle net of R1 ("waiting") is drawn
                await expect(page.get_by_role("region", name="Net waiting")).to_be_visible()
                await expect(page.get_by_role("button", name="Kill waiting")).to_be_visible()
            await web.axe_check(page)
            await web.screenshot(page, name)
            # The view scrolls in its own box; the page itself never scrolls to a blank
            # screen (visually hidden labels once stretched it).
            page_height = await page.evaluate("() => document.documentElement.scrollHeight")
            assert page_height <= (page.viewport_size or {}).get("height", 0), name

        operator = await open_page(fleet.admin_url)
        await web.sign_in(operator, web.operator_token)
        await expect(operator.page.locator("#who")).to_contain_text("operator")
        # Its snapshot first (R1 on its map), as the admin's page above: the monitor draws
        # the nets the snapshot brings.
        await expect(operator.page.get_by_role("button", name="robot R1")).to_be_visible(
            timeout=20_000
        )
        await web.open_view(operator.page, "RoboGraph monitor")
        await expect(operator.page.get_by_role("region", name="Net waiting")).to_be_visible()
        await expect(operator.page.get_by_role("button", name="Kill waiting")).to_have_count(0)
        await web.open_view(operator.page, "Locks")
        await expect(operator.page.get_by_text("Operators may release")).to_be_visible()
        # The server enforces the same rules.
        async with fleet.http(web.operator_token) as http:
            running = (await http.get("/api/nets/running", params={"target": "R1"})).json()
            body = {"target": "R1", "instance_id": running[0]["instance_id"]}
            refused = await http.post("/api/nets/kill", json=body)
            assert refused.status_code == 403
            held = await http.post("/api/locks/corridor/release")
            assert held.status_code == 403 and "holder is offline" in held.json()["detail"]


async def test_tour_requested_from_the_console_runs_to_the_end(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=1, time_scale=8, edit=short_tours) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        await expect(page.get_by_role("button", name="robot R1")).to_be_visible(timeout=20_000)
        start = await page.evaluate(ON_PLAN)
        await web.open_view(page, "Tasks")
        await page.get_by_label("Target").select_option("short")
        await page.get_by_role("button", name="Request task").click()
        await expect(
            page.get_by_role("status").filter(has_text="Request tour: done")
        ).to_be_visible()
        running = page.get_by_role("table", name="Running tasks")
        await expect(running).to_contain_text("Tour: Short tour", timeout=20_000)
        # On the map, the selected robot's planned path is drawn.
        await web.open_view(page, "Map")
        # The element, not a point: a moving marker (or one moved aside) can be missed.
        await page.get_by_role("button", name="robot R1").dispatch_event("click")
        await expect(page.locator("#details")).to_contain_text("Robot R1")
        await expect(page.locator("#map path.map-path")).to_have_count(1, timeout=20_000)
        # The monitor shows the tour's net and its marking changing.
        await web.open_view(page, "RoboGraph monitor")
        await page.get_by_label("Show the nets of").select_option("R1")
        net = page.get_by_role("region", name="Net give_tour")
        await expect(net).to_be_visible(timeout=20_000)
        before = await net.locator("[data-place]").evaluate_all(
            "els => els.map(e => e.dataset.tokens).join(',')"
        )
        await page.wait_for_function(
            """before => {
                const net = document.querySelector('[aria-label="Net give_tour"]');
                if (!net) return true;  // ended: the marking certainly changed
                const now = [...net.querySelectorAll('[data-place]')].map(e => e.dataset.tokens);
                return now.join(',') !== before;
            }""",
            arg=before,
            timeout=30_000,
        )
        # The robot moved on the map.
        await web.open_view(page, "Map")
        await page.wait_for_function(
            f"""start => {{
                const at = ({ON_PLAN})();
                return Math.hypot(at[0] - start[0], at[1] - start[1]) > 0.02;
            }}""",
            arg=start,
            timeout=30_000,
        )
        await web.open_view(page, "Tasks")
        finished = page.get_by_role("table", name="Finished tasks")
        await expect(
            finished.get_by_role("row").filter(has_text="Tour: Short tour")
        ).to_contain_text("done", timeout=60_000)


async def test_robot_lost_mid_tour_shows_lost_and_its_lock_can_be_released(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    # R1 starts at its station (charge_a): the start at ga1 this test once asked for was never
    # applied (the fleet fixture ignored edited start nodes) and, applied, leaves the corridor
    # sometimes found free after the kill: a scenario of its own, not this test's.
    async with fleet_factory(robots=1, time_scale=4, edit=short_tours) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, web.operator_token)
        await expect(page.get_by_role("button", name="robot R1")).to_be_visible(timeout=20_000)
        held = asyncio.Event()

        def on_lock(message: Message) -> None:
            if message.payload["area"] == "corridor" and message.payload["holder"] == "R1":
                held.set()

        fleet.server.app.state.hub.endpoint("test").subscribe("lock_changed", on_lock, tap=True)
        async with fleet.http() as http:
            r = await http.post("/api/tasks", json={"kind": "tour", "params": {"tour": "east"}})
            assert r.status_code == 201
        await asyncio.wait_for(held.wait(), 30)
        await fleet.kill("R1")
        await web.open_view(page, "Robots")
        await expect(page.get_by_role("heading", name="R1")).to_contain_text("lost", timeout=20_000)
        await expect(page.locator("#alert-bar")).to_contain_text("open alert")
        assert (await page.title()).startswith("(")
        await web.open_view(page, "Locks")
        row = page.get_by_role("row").filter(has_text="corridor")
        await expect(row).to_contain_text("holder offline", timeout=20_000)
        await web.axe_check(page)
        await row.get_by_role("button", name="Force release corridor").click()
        dialog = page.get_by_role("dialog")
        await expect(dialog).to_contain_text("R1 holds it and is offline")
        await web.screenshot(page, "locks-release")
        await dialog.get_by_role("button", name="Release corridor").click()
        await expect(row).to_contain_text("free")
        await web.open_view(page, "Alerts")
        lost = page.get_by_role("row").filter(has_text="R1 lost its connection")
        await lost.get_by_role("button", name="Acknowledge").click()
        await expect(lost).to_contain_text("by desk at")


async def test_building_view_shows_a_door_opening_and_presses_a_button(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace
) -> None:
    async with fleet_factory(robots=0) as fleet:
        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        await web.open_view(page, "Building")
        door = page.locator('[data-door="door_gallery"]')
        await expect(door).to_have_text("closed", timeout=20_000)
        sensor = page.locator('[data-point="otb_ground/door_hall_is_open"]')
        await expect(sensor).to_have_text("off")
        endpoint = fleet.server.app.state.hub.endpoint("test")
        endpoint.publish("open_door", {"door": "door_gallery"})
        await expect(door).to_have_text("open", timeout=20_000)
        await web.screenshot(page, "building")
        await expect(door).to_have_text("closed", timeout=30_000)
        await page.get_by_role("button", name="Press button_entrance").click()
        await web.open_view(page, "Tasks")
        queue = page.get_by_role("table", name="Queued tasks")
        await expect(queue).to_contain_text("Tour: Ground floor tour", timeout=20_000)


async def test_alerts_survive_a_reload_and_a_restart_resolves_the_stale_ones(
    tmp_path: Path, open_page: Any, web: SimpleNamespace
) -> None:
    """Kept across a restart, but what the last server life saw is not known to be current:
    resolved (a cause that persists is raised again by whoever sees it)."""
    settings = Settings(db_url=f"sqlite+aiosqlite:///{tmp_path}/t.db", building_enabled=False)
    async with running_server(settings) as server:
        port = server.port
        watch = await open_page(f"{server.url}/admin/")
        # It watches the server go and come back: the refused reconnections are expected (and
        # the page stays open when the server stops, tests/web/conftest.py open_page).
        watch.expect_error(r"WebSocket connection to .* failed")
        watch.expect_error(r"net::ERR_CONNECTION_REFUSED")
        page = watch.page
        await web.sign_in(watch, server.admin_token)
        alerts = server.app.state.alerts
        alerts.raise_("robot_lost", "R1", "robot R1 lost its connection")
        alerts.raise_("module_offline", "otb_ground", "Modbus module otb_ground: no answer")
        await expect(page.locator("#alert-bar")).to_contain_text("2 open alerts")
        assert (await page.title()).startswith("(2)")
        await web.open_view(page, "Alerts")
        row = page.get_by_role("row").filter(has_text="R1 lost")
        await row.get_by_role("button", name="Acknowledge").click()
        await expect(row).to_contain_text("by admin at")
        await expect(page.locator("#alert-bar")).to_contain_text("1 open alert")
    banner = page.get_by_role("status").filter(has_text="Connection lost, reconnecting")
    await expect(banner).to_be_visible(timeout=20_000)
    async with running_server(settings, port=port) as server:
        await expect(banner).to_be_hidden(timeout=30_000)
        await expect(page.locator("#alert-bar")).to_be_hidden()
        await page.reload()
        await web.open_view(page, "Alerts")
        lost = page.get_by_role("row").filter(has_text="R1 lost")
        await expect(lost).to_contain_text("by admin at")
        await expect(lost).to_have_attribute("data-state", "resolved")
        stale = page.get_by_role("row").filter(has_text="otb_ground")
        await expect(stale).to_contain_text("server restarted")
        await expect(page.locator("#alert-bar")).to_be_hidden()
        await web.axe_check(page)
