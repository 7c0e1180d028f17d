"""A real robot agent on a virtual CAN bus: its ``robocan_status`` reaches the server over the
hub (rate-limited by its link) and the console's robot view shows its modules, their state and
counters, live."""

from __future__ import annotations

import uuid
from types import SimpleNamespace
from typing import Any

import pytest
from playwright.async_api import expect

from guidebot.testing import wait_until
from robot_agent.agent import AgentConfig, RobotAgent

pytestmark = [pytest.mark.browser, pytest.mark.timeout(120)]


async def test_the_robot_view_shows_the_can_modules_a_robot_reports(
    fleet_factory: Any, open_page: Any, web: SimpleNamespace, demo_site: Any
) -> None:
    async with fleet_factory(robots=0) as fleet:
        channel = f"virtual:console-{uuid.uuid4().hex[:8]}"
        robot = demo_site.robots[0]
        agent = RobotAgent(
            AgentConfig(
                name=robot.name,
                server=fleet.server.url,
                token=robot.token,
                can=channel,
                time_scale=5.0,
                start_node=robot.start_node,
                speech_engine=None,
                site=fleet.site_file,
            )
        )
        await agent.__aenter__()
        fleet.agents[robot.name] = agent  # stopped with the fleet
        stack = agent.hardware.stack  # type: ignore[union-attr]
        await stack.wait_online(timeout=30)

        watch = await open_page(fleet.admin_url)
        page = watch.page
        await web.sign_in(watch, fleet.server.admin_token)
        await web.open_view(page, "Robots")
        table = page.get_by_role("table", name=f"RoboCAN modules of R1 on {channel}")
        expected = stack.module_table()
        assert len(expected) >= 5
        for row in expected:
            cells = table.locator(f'tr[data-module="{row["module_id"]}"]')
            await expect(cells).to_contain_text(row["name"], timeout=20_000)
            await expect(cells).to_contain_text(row["kind"])
            await expect(cells).to_contain_text(row["firmware"])
            await expect(cells).to_contain_text("online")
        await expect(table.locator("caption")).to_contain_text("frames received")

        # The server keeps the latest one, typed, for the REST API.
        async with fleet.http() as http:
            detail = (await http.get("/api/robots/R1")).json()
        robocan = detail["robocan"]
        (bus,) = robocan["buses"]
        assert robocan["robot"] == "R1" and bus["bus"] == channel
        assert {m["module_id"] for m in bus["modules"]} == {r["module_id"] for r in expected}
        assert bus["counters"]["frames_rx"] > 0

        # A sonar ring goes away: its loss shows at once (a state change is not held back
        # by the link's rate limit), with the master's loss counter.
        agent.bus.endpoint("operator").publish("module_plug", {"module_id": 0x20, "plugged": False})
        sonar = table.locator('tr[data-module="32"]')
        await expect(sonar).to_contain_text("lost", timeout=20_000)
        await expect(table.locator("caption")).to_contain_text("modules lost: 1")
        link = agent.link
        assert link is not None
        # On board every second; with no module changing, the next ones are held back (at most
        # every 5 s): one is held, and the server still has the one that said "lost".
        async with fleet.http() as http:
            before = (await http.get("/api/robots/R1")).json()["robocan"]["at"]
            await wait_until(lambda: link.robocan.held > 0, timeout=30)
            after = (await http.get("/api/robots/R1")).json()["robocan"]["at"]
        assert after == before
        await web.axe_check(page)
        await web.screenshot(page, "robots-robocan")
